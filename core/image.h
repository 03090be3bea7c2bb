#pragma once
// RGBA8 images (row 0 at the top) and PNG files.
#include <cstdint>
#include <string>
#include <vector>

namespace tessera {

struct Image {
  int32_t width = 0, height = 0;
  std::vector<uint8_t> rgba;  // width * height * 4

  Image() = default;
  Image(int32_t w, int32_t h) : width(w), height(h), rgba(size_t(w) * h * 4, 0) {}
  uint8_t* pixel(int32_t x, int32_t y) { return &rgba[(size_t(y) * width + x) * 4]; }
  const uint8_t* pixel(int32_t x, int32_t y) const { return &rgba[(size_t(y) * width + x) * 4]; }
};

// Writes a PNG; throws std::runtime_error naming the file on failure.
void write_png(const std::string& path, const Image& img);
// Reads a PNG or JPEG into RGBA8; throws std::runtime_error naming the file on failure.
Image read_image(const std::string& path);
// Decodes an in-memory PNG/JPEG; returns false and sets error on failure (any other format:
// "not a PNG or JPEG image"). JPEGs are decoded by libjpeg-turbo (jpeg_decode: the San
// Miguel-sized scene's 222 textures in 1.4 s instead of stb_image's 2.0 s,
// docs/results/load.md); stb_image decodes PNGs and the JPEGs libjpeg-turbo cannot (such as
// CMYK ones), but not those it refuses as too large.
bool decode_image(const uint8_t* data, size_t size, Image& out, std::string& error);
// Decodes a JPEG into RGBA8 (alpha 255) with libjpeg-turbo. Creates a handle per call (so any
// thread may call it). Progressive files with an unreasonable number of scans are rejected
// (TJFLAG_LIMITSCANS), so client-sent textures cannot make decoding take minutes.
// A JPEG whose header declares more than kMaxDecodedPixels (a 16384 x 16384 image, 1 GiB as
// RGBA8) is refused before anything is allocated.
constexpr int64_t kMaxDecodedPixels = int64_t(1) << 28;
bool jpeg_decode(const uint8_t* data, size_t size, Image& out, std::string& error);

// A PNG's size from its signature and IHDR chunk (big-endian width and height), read before
// decoding so a caller can refuse an image larger than its limit; false: not a PNG.
bool png_dimensions(const uint8_t* data, size_t size, uint32_t& width, uint32_t& height);

// Copies src into dst at (x, y); src must fit.
void blit(Image& dst, const Image& src, int32_t x, int32_t y);

// Image comparison over RGB (alpha ignored): root mean square error in 0..255 units and
// PSNR in dB (infinite for identical images). Sizes must match.
struct ImageError {
  double rmse = 0;
  double psnr = 0;
};
ImageError compare(const Image& a, const Image& b);

}  // namespace tessera
