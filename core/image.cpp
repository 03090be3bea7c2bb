#include "core/image.h"

#include <cmath>
#include <cstring>
#include <limits>
#include <stdexcept>

#define STB_IMAGE_IMPLEMENTATION
#define STB_IMAGE_WRITE_IMPLEMENTATION
#define STBI_FAILURE_USERMSG
// Each side at most 16384 (kMaxDecodedPixels in all): a header cannot make stb_image allocate more.
#define STBI_MAX_DIMENSIONS 16384
// PNG and JPEG only (all glTF 2.0 and the protocol allow). stb_image's other readers (PSD, BMP,
// TGA, HDR, PIC, PNM, GIF) allocate and fill the header's size whatever data follows: a
// 30-byte PSD header in a glTF data: URI made it allocate and write 1 GiB.
#define STBI_ONLY_PNG
#define STBI_ONLY_JPEG
#if defined(__GNUC__)
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wmissing-field-initializers"
#pragma GCC diagnostic ignored "-Wsign-compare"
#pragma GCC diagnostic ignored "-Wunused-function"
#endif
#include <stb_image.h>
#include <stb_image_write.h>
#if defined(__GNUC__)
#pragma GCC diagnostic pop
#endif
#include <turbojpeg.h>

namespace tessera {

void write_png(const std::string& path, const Image& img) {
  if (img.width <= 0 || img.height <= 0) throw std::runtime_error(path + ": cannot write an empty image");
  if (!stbi_write_png(path.c_str(), img.width, img.height, 4, img.rgba.data(), img.width * 4))
    throw std::runtime_error(path + ": could not write PNG");
}

bool png_dimensions(const uint8_t* p, size_t n, uint32_t& w, uint32_t& h) {
  static const uint8_t sig[8] = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n'};
  if (n < 24 || std::memcmp(p, sig, 8) != 0 || std::memcmp(p + 12, "IHDR", 4) != 0) return false;
  w = (uint32_t(p[16]) << 24) | (uint32_t(p[17]) << 16) | (uint32_t(p[18]) << 8) | p[19];
  h = (uint32_t(p[20]) << 24) | (uint32_t(p[21]) << 16) | (uint32_t(p[22]) << 8) | p[23];
  return true;
}

namespace {

enum class Jpeg { ok, too_large, failed };

// libjpeg-turbo's decoding; too_large: the header declares more than kMaxDecodedPixels, and
// nothing was allocated.
Jpeg turbo_decode(const uint8_t* data, size_t size, Image& out, std::string& error) {
  tjhandle h = tjInitDecompress();
  if (!h) {
    error = "jpeg: could not create a TurboJPEG decompressor";
    return Jpeg::failed;
  }
  int w = 0, hgt = 0, subsamp = 0, colorspace = 0;
  Jpeg r = tjDecompressHeader3(h, data, static_cast<unsigned long>(size), &w, &hgt, &subsamp, &colorspace) == 0 ? Jpeg::ok : Jpeg::failed;
  if (r == Jpeg::ok && int64_t(w) * hgt > kMaxDecodedPixels) {
    error = "jpeg: " + std::to_string(w) + "x" + std::to_string(hgt) + " is more than " + std::to_string(kMaxDecodedPixels) +
            " pixels; not decoded";
    r = Jpeg::too_large;
  } else if (r == Jpeg::ok) {
    out = Image(w, hgt);
    if (tjDecompress2(h, data, static_cast<unsigned long>(size), out.rgba.data(), w, 0, hgt, TJPF_RGBA, TJFLAG_LIMITSCANS) != 0)
      r = Jpeg::failed;
  }
  if (r == Jpeg::failed) error = std::string("jpeg: ") + tjGetErrorStr2(h);
  tjDestroy(h);
  return r;
}

}  // namespace

bool decode_image(const uint8_t* data, size_t size, Image& out, std::string& error) {
  if (size > size_t(std::numeric_limits<int>::max())) {
    error = "image data too large";
    return false;
  }
  static const uint8_t png_sig[8] = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n'};
  const bool jpeg = size >= 3 && data[0] == 0xFF && data[1] == 0xD8 && data[2] == 0xFF;
  if (!jpeg && !(size >= 8 && std::memcmp(data, png_sig, 8) == 0)) {
    error = "not a PNG or JPEG image";
    return false;
  }
  if (jpeg) {
    std::string jpeg_error;
    switch (turbo_decode(data, size, out, jpeg_error)) {
      case Jpeg::ok: return true;
      case Jpeg::too_large: error = jpeg_error; return false;
      case Jpeg::failed: break;  // stb_image may still read it (CMYK, for one); its error is the one reported
    }
  }
  int w = 0, h = 0, n = 0;
  stbi_uc* px = stbi_load_from_memory(data, int(size), &w, &h, &n, 4);
  if (!px) {
    error = stbi_failure_reason() ? stbi_failure_reason() : "undecodable image";
    return false;
  }
  out.width = w;
  out.height = h;
  out.rgba.assign(px, px + size_t(w) * h * 4);
  stbi_image_free(px);
  return true;
}

bool jpeg_decode(const uint8_t* data, size_t size, Image& out, std::string& error) {
  return turbo_decode(data, size, out, error) == Jpeg::ok;
}

Image read_image(const std::string& path) {
  int w = 0, h = 0, n = 0;
  stbi_uc* px = stbi_load(path.c_str(), &w, &h, &n, 4);
  if (!px) throw std::runtime_error(path + ": " + (stbi_failure_reason() ? stbi_failure_reason() : "cannot read image"));
  Image img(w, h);
  std::memcpy(img.rgba.data(), px, img.rgba.size());
  stbi_image_free(px);
  return img;
}

void blit(Image& dst, const Image& src, int32_t x, int32_t y) {
  for (int32_t row = 0; row < src.height; ++row)
    std::memcpy(dst.pixel(x, y + row), src.pixel(0, row), size_t(src.width) * 4);
}

ImageError compare(const Image& a, const Image& b) {
  if (a.width != b.width || a.height != b.height) throw std::runtime_error("compare: image sizes differ");
  double se = 0;
  size_t n = size_t(a.width) * a.height;
  for (size_t i = 0; i < n; ++i)
    for (int c = 0; c < 3; ++c) {
      double d = double(a.rgba[i * 4 + c]) - double(b.rgba[i * 4 + c]);
      se += d * d;
    }
  ImageError e;
  double mse = n ? se / double(n * 3) : 0;
  e.rmse = std::sqrt(mse);
  e.psnr = mse > 0 ? 10.0 * std::log10(255.0 * 255.0 / mse) : std::numeric_limits<double>::infinity();
  return e;
}

}  // namespace tessera
