#include "codecs/jpeg.h"

#include <turbojpeg.h>

#include <utility>

namespace tessera {

JpegEncoder::JpegEncoder() : handle_(tjInitCompress()) {}
JpegEncoder::~JpegEncoder() {
  if (handle_) tjDestroy(static_cast<tjhandle>(handle_));
}
JpegEncoder::JpegEncoder(JpegEncoder&& o) noexcept : handle_(std::exchange(o.handle_, nullptr)) {}
JpegEncoder& JpegEncoder::operator=(JpegEncoder&& o) noexcept {
  std::swap(handle_, o.handle_);
  return *this;
}

bool JpegEncoder::encode(const uint8_t* rgba, int width, int height, int quality, std::vector<uint8_t>& out,
                         std::string& error, size_t offset) {
  if (!handle_) {
    error = "jpeg: could not create a TurboJPEG compressor";
    return false;
  }
  if (width <= 0 || height <= 0 || !rgba) {
    error = "jpeg: empty image " + std::to_string(width) + "x" + std::to_string(height);
    return false;
  }
  if (quality < 1 || quality > 100) {
    error = "jpeg: quality " + std::to_string(quality) + " outside 1..100";
    return false;
  }
  if (offset > out.size()) out.resize(offset);
  // Encode straight into `out`: tjBufSize is the worst case, and TJFLAG_NOREALLOC keeps
  // libjpeg-turbo from replacing our buffer.
  unsigned long max_size = tjBufSize(width, height, TJSAMP_420);
  if (max_size == static_cast<unsigned long>(-1)) {
    error = std::string("jpeg: ") + tjGetErrorStr2(static_cast<tjhandle>(handle_));
    return false;
  }
  out.resize(offset + max_size);
  unsigned char* dst = out.data() + offset;
  unsigned long size = max_size;
  if (tjCompress2(static_cast<tjhandle>(handle_), rgba, width, 0, height, TJPF_RGBA, &dst, &size, TJSAMP_420,
                  quality, TJFLAG_NOREALLOC) != 0) {
    error = std::string("jpeg: ") + tjGetErrorStr2(static_cast<tjhandle>(handle_));
    out.resize(offset);
    return false;
  }
  out.resize(offset + size);
  return true;
}

bool jpeg_dimensions(const uint8_t* data, size_t size, int& width, int& height, std::string& error) {
  tjhandle h = tjInitDecompress();
  if (!h) {
    error = "jpeg: could not create a TurboJPEG decompressor";
    return false;
  }
  int subsamp = 0, colorspace = 0;
  bool ok = tjDecompressHeader3(h, data, static_cast<unsigned long>(size), &width, &height, &subsamp, &colorspace) == 0;
  if (!ok) error = std::string("jpeg: ") + tjGetErrorStr2(h);
  tjDestroy(h);
  return ok;
}

}  // namespace tessera
