#pragma once
// JPEG display encoding with libjpeg-turbo's TurboJPEG API (4:2:0 chroma subsampling).
#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "core/image.h"

namespace tessera {

// A reusable JPEG encoder: owns one TurboJPEG compressor handle for its whole life, so
// encoding a frame creates no handle. Not thread-safe: one encoder per encoding thread.
class JpegEncoder {
 public:
  JpegEncoder();
  ~JpegEncoder();
  JpegEncoder(const JpegEncoder&) = delete;
  JpegEncoder& operator=(const JpegEncoder&) = delete;
  JpegEncoder(JpegEncoder&& o) noexcept;
  JpegEncoder& operator=(JpegEncoder&& o) noexcept;

  // Encodes width x height RGBA8 pixels (row 0 at the top, alpha ignored) at quality
  // 1..100 with 4:2:0 subsampling. The JPEG is written into `out` starting at `offset`
  // (bytes before it are kept, so a caller can put a message header first); `out` is
  // resized to offset + JPEG size and its capacity is reused across frames.
  // Returns false and sets `error` on failure (bad arguments, libjpeg-turbo error).
  bool encode(const uint8_t* rgba, int width, int height, int quality, std::vector<uint8_t>& out,
              std::string& error, size_t offset = 0);
  bool encode(const Image& img, int quality, std::vector<uint8_t>& out, std::string& error, size_t offset = 0) {
    return encode(img.rgba.data(), img.width, img.height, quality, out, error, offset);
  }

 private:
  void* handle_ = nullptr;  // tjhandle
};

// Reads width and height from a JPEG header without decoding the image.
bool jpeg_dimensions(const uint8_t* data, size_t size, int& width, int& height, std::string& error);
// Decoding a JPEG: jpeg_decode in core/image.h (the glTF loader decodes with it too).

}  // namespace tessera
