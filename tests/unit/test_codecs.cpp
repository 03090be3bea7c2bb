// Codecs: JPEG and DXT1 round trips with PSNR bounds, the reference DXT1 decoder against
// libsquish, and zlib inflation limits.
#include <catch2/catch.hpp>
#include <squish.h>
#include <tbb/global_control.h>

#include <cmath>
#include <cstring>
#include <random>

#include "codecs/deflate.h"
#include "codecs/dxt1.h"
#include "codecs/jpeg.h"

using namespace tessera;

namespace {

// A smooth image: gradients and low-frequency waves (what shaded surfaces look like), at the
// scale of a 1280x720 frame whatever the size (a 5x3 image is its top-left corner).
Image smooth_image(int w, int h) {
  Image img(w, h);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      float u = float(x) / 1279, v = float(y) / 719;
      uint8_t* p = img.pixel(x, y);
      p[0] = uint8_t(255 * u);
      p[1] = uint8_t(255 * v);
      p[2] = uint8_t(127.5f + 127.5f * std::sin(6.2832f * (u + v)));
      p[3] = 255;
    }
  return img;
}

// A noisy image: the smooth one plus uniform noise of +-40 per channel (worst case for both).
Image noisy_image(int w, int h, uint32_t seed = 7) {
  Image img = smooth_image(w, h);
  std::mt19937 rng(seed);
  std::uniform_int_distribution<int> d(-40, 40);
  for (size_t i = 0; i < img.rgba.size(); ++i)
    if (i % 4 != 3) img.rgba[i] = uint8_t(std::clamp(int(img.rgba[i]) + d(rng), 0, 255));
  return img;
}

double jpeg_psnr(const Image& img, int quality, size_t* bytes = nullptr) {
  JpegEncoder enc;
  std::vector<uint8_t> out;
  std::string err;
  REQUIRE(enc.encode(img, quality, out, err));
  if (bytes) *bytes = out.size();
  Image back;
  REQUIRE(jpeg_decode(out.data(), out.size(), back, err));
  REQUIRE(back.width == img.width);
  REQUIRE(back.height == img.height);
  return compare(img, back).psnr;
}

double dxt1_psnr(const Image& img, Dxt1Fit fit) {
  std::vector<uint8_t> blocks;
  dxt1_encode(img, fit, blocks);
  REQUIRE(blocks.size() == dxt1_size(img.width, img.height));
  return compare(img, dxt1_decode(blocks.data(), img.width, img.height)).psnr;
}

}  // namespace

TEST_CASE("JPEG round trip of a smooth 1280x720 image keeps PSNR above 45 dB at q85", "[codecs][jpeg]") {
  Image img = smooth_image(1280, 720);
  size_t bytes = 0;
  CHECK(jpeg_psnr(img, 85, &bytes) > 45.0);  // measured 49.3
  CHECK(bytes < 200000);
  CHECK(jpeg_psnr(img, 95) > jpeg_psnr(img, 50));
}

TEST_CASE("JPEG round trip of a noisy image keeps PSNR above 20 dB at q85", "[codecs][jpeg]") {
  CHECK(jpeg_psnr(noisy_image(640, 360), 85) > 20.0);  // measured 22.5
}

TEST_CASE("JPEG encodes odd sizes 1x1, 5x3 and 1281x721", "[codecs][jpeg]") {
  CHECK(jpeg_psnr(smooth_image(1, 1), 90) > 30.0);
  CHECK(jpeg_psnr(smooth_image(5, 3), 90) > 25.0);
  CHECK(jpeg_psnr(smooth_image(1281, 721), 85) > 45.0);
  CHECK(jpeg_psnr(noisy_image(5, 3), 90) > 20.0);
}

TEST_CASE("JPEG encoder is reusable and writes after a caller's header", "[codecs][jpeg]") {
  JpegEncoder enc;
  std::string err;
  std::vector<uint8_t> a, b{1, 2, 3};
  Image img = smooth_image(64, 48);
  REQUIRE(enc.encode(img, 75, a, err));
  REQUIRE(enc.encode(img, 75, b, err, 3));
  REQUIRE(b.size() == a.size() + 3);
  CHECK(b[0] == 1);
  CHECK(b[2] == 3);
  CHECK(std::memcmp(a.data(), b.data() + 3, a.size()) == 0);
  int w = 0, h = 0;
  REQUIRE(jpeg_dimensions(a.data(), a.size(), w, h, err));
  CHECK(w == 64);
  CHECK(h == 48);
}

TEST_CASE("JPEG encoder rejects bad quality and empty images with a message", "[codecs][jpeg]") {
  JpegEncoder enc;
  std::string err;
  std::vector<uint8_t> out;
  Image img = smooth_image(8, 8);
  CHECK_FALSE(enc.encode(img, 0, out, err));
  CHECK(err.find("quality") != std::string::npos);
  CHECK_FALSE(enc.encode(img, 101, out, err));
  CHECK_FALSE(enc.encode(Image(), 80, out, err));
  CHECK(err.find("empty") != std::string::npos);
  Image back;
  uint8_t junk[16] = {0xff, 0xd8, 1, 2, 3};
  CHECK_FALSE(jpeg_decode(junk, sizeof junk, back, err));
}

TEST_CASE("a JPEG that declares a huge size is refused before decoding, by jpeg_decode and decode_image", "[codecs][jpeg]") {
  JpegEncoder enc;
  std::vector<uint8_t> jpeg;
  std::string err;
  REQUIRE(enc.encode(smooth_image(16, 16), 80, jpeg, err));
  // The frame header (SOF0: FF C0, length, precision, height, width): claim 60000 x 60000.
  size_t sof = 0;
  for (size_t i = 2; i + 9 < jpeg.size(); ++i)
    if (jpeg[i] == 0xFF && jpeg[i + 1] == 0xC0) { sof = i; break; }
  REQUIRE(sof > 0);
  for (size_t k : {sof + 5, sof + 7}) { jpeg[k] = 0xEA; jpeg[k + 1] = 0x60; }  // 60000
  Image back;
  CHECK_FALSE(jpeg_decode(jpeg.data(), jpeg.size(), back, err));
  CHECK(err.find("60000x60000 is more than") != std::string::npos);
  CHECK(back.rgba.empty());
  // decode_image (the glTF loader's) refuses it too, without handing it to stb_image (which
  // would allocate 14 GB for it).
  CHECK_FALSE(decode_image(jpeg.data(), jpeg.size(), back, err));
  CHECK(err.find("60000x60000 is more than") != std::string::npos);
  // And an ordinary JPEG decodes through both, to the same pixels.
  REQUIRE(enc.encode(smooth_image(16, 16), 80, jpeg, err));
  Image a, b;
  REQUIRE(jpeg_decode(jpeg.data(), jpeg.size(), a, err));
  REQUIRE(decode_image(jpeg.data(), jpeg.size(), b, err));
  CHECK(a.width == 16);
  CHECK(a.rgba == b.rgba);
}

TEST_CASE("decode_image reads PNG and JPEG only: other formats are refused before anything is allocated", "[codecs]") {
  // Fuzz finding gltf_psd_header_1GiB: a 30-byte PSD header claiming 16384 x 16384 made
  // stb_image allocate and fill 1 GiB with no pixel data behind it. Its other formats (BMP,
  // TGA, GIF, HDR, PNM, PIC) are refused the same way.
  std::vector<uint8_t> psd = {'8', 'B', 'P', 'S', 0, 1, 0, 0, 0, 0, 0, 0, 0, 3, 0, 0, 0x40, 0, 0, 0, 0x40, 0, 0, 8, 0, 3};
  psd.resize(psd.size() + 14, 0);  // empty colour, resource and layer sections; raw data, none of it there
  const std::vector<uint8_t> bmp = {'B', 'M', 0, 0, 0, 0, 0, 0, 0, 0, 54, 0, 0, 0, 40, 0, 0, 0, 0, 0x40, 0, 0, 0, 0x40, 0, 0, 1, 0, 24, 0};
  const std::vector<uint8_t> pnm = {'P', '6', '\n', '1', '6', '3', '8', '4', ' ', '1', '6', '3', '8', '4', '\n', '2', '5', '5', '\n'};
  const std::vector<uint8_t>* inputs[] = {&psd, &bmp, &pnm};
  for (const std::vector<uint8_t>* bytes : inputs) {
    Image back;
    std::string err;
    CHECK_FALSE(decode_image(bytes->data(), bytes->size(), back, err));
    CHECK(err == "not a PNG or JPEG image");
    CHECK(back.rgba.empty());
  }
  Image back;
  std::string err;
  CHECK_FALSE(decode_image(psd.data(), 0, back, err));
  CHECK(err == "not a PNG or JPEG image");
}

TEST_CASE("DXT1 sizes are ceil(w/4)*ceil(h/4)*8", "[codecs][dxt1]") {
  CHECK(dxt1_size(1, 1) == 8);
  CHECK(dxt1_size(5, 3) == 16);
  CHECK(dxt1_size(1280, 720) == 320 * 180 * 8);
  CHECK(dxt1_size(1281, 721) == 321 * 181 * 8);
  CHECK(dxt1_size(0, 5) == 0);
}

TEST_CASE("DXT1 round trip keeps PSNR above 40 dB (range) and 42 dB (cluster) on a smooth image",
          "[codecs][dxt1]") {
  Image img = smooth_image(1280, 720);
  double range = dxt1_psnr(img, Dxt1Fit::range), cluster = dxt1_psnr(img, Dxt1Fit::cluster);
  CHECK(range > 40.0);  // measured 43.8
  CHECK(cluster > 42.0);  // measured 45.2
  CHECK(cluster >= range - 0.1);
}

TEST_CASE("DXT1 round trip of a noisy image keeps PSNR above 22 dB", "[codecs][dxt1]") {
  Image img = noisy_image(320, 180);
  CHECK(dxt1_psnr(img, Dxt1Fit::range) > 22.0);  // measured 23.8
  CHECK(dxt1_psnr(img, Dxt1Fit::cluster) > 22.0);
}

TEST_CASE("DXT1 encodes odd sizes 1x1, 5x3 and 1281x721", "[codecs][dxt1]") {
  CHECK(dxt1_psnr(smooth_image(1, 1), Dxt1Fit::range) > 40.0);
  CHECK(dxt1_psnr(smooth_image(5, 3), Dxt1Fit::range) > 30.0);
  CHECK(dxt1_psnr(smooth_image(1281, 721), Dxt1Fit::range) > 40.0);
  CHECK(dxt1_psnr(noisy_image(5, 3), Dxt1Fit::cluster) > 18.0);
}

TEST_CASE("DXT1 output does not depend on the thread count", "[codecs][dxt1]") {
  Image img = noisy_image(257, 131);
  std::vector<uint8_t> one, many;
  {
    tbb::global_control c(tbb::global_control::max_allowed_parallelism, 1);
    dxt1_encode(img, Dxt1Fit::range, one);
  }
  dxt1_encode(img, Dxt1Fit::range, many);
  CHECK(one == many);
}

TEST_CASE("Reference DXT1 decoder equals squish::DecompressImage on squish's blocks", "[codecs][dxt1]") {
  for (auto [w, h] : {std::pair{1280, 720}, std::pair{5, 3}, std::pair{1281, 721}, std::pair{1, 1}}) {
    for (Dxt1Fit fit : {Dxt1Fit::range, Dxt1Fit::cluster}) {
      Image img = noisy_image(w, h, uint32_t(w * 31 + h));
      std::vector<uint8_t> blocks;
      dxt1_encode(img, fit, blocks);
      Image ours = dxt1_decode(blocks.data(), w, h, /*transparent_black=*/true);
      Image theirs(w, h);
      squish::DecompressImage(theirs.rgba.data(), w, h, blocks.data(), squish::kDxt1);
      CHECK(ours.rgba == theirs.rgba);
    }
  }
}

TEST_CASE("Reference DXT1 decoder covers both block modes", "[codecs][dxt1]") {
  // color0 = white > color1 = black: four-colour mode, indices 0,1,2,3 across the first row.
  uint8_t four[8] = {0xff, 0xff, 0x00, 0x00, 0b11100100, 0, 0, 0};
  Image a = dxt1_decode(four, 4, 4);
  CHECK(a.pixel(0, 0)[0] == 255);
  CHECK(a.pixel(1, 0)[0] == 0);
  CHECK(a.pixel(2, 0)[0] == 170);
  CHECK(a.pixel(3, 0)[0] == 85);
  // color0 = black <= color1 = white: three-colour mode, index 3 black (opaque for RGB).
  uint8_t three[8] = {0x00, 0x00, 0xff, 0xff, 0b11100100, 0, 0, 0};
  Image b = dxt1_decode(three, 4, 4);
  CHECK(b.pixel(2, 0)[0] == 127);
  CHECK(b.pixel(3, 0)[0] == 0);
  CHECK(b.pixel(3, 0)[3] == 255);
  CHECK(dxt1_decode(three, 4, 4, true).pixel(3, 0)[3] == 0);
  // Each 4-bit indices byte holds one row, texel x at bits 2x.
  uint8_t rows[8] = {0xff, 0xff, 0x00, 0x00, 0, 0x55, 0, 0};
  Image c = dxt1_decode(rows, 4, 4);
  CHECK(c.pixel(0, 0)[1] == 255);
  CHECK(c.pixel(0, 1)[1] == 0);
}

TEST_CASE("Deflate round trip in the zlib format (78 9c, like CompressionStream)", "[codecs][deflate]") {
  std::vector<uint8_t> data(100000);
  for (size_t i = 0; i < data.size(); ++i) data[i] = uint8_t((i * 7) ^ (i >> 5));
  auto z = deflate_zlib(data.data(), data.size());
  REQUIRE(z.size() > 2);
  CHECK(z[0] == 0x78);
  CHECK(z[1] == 0x9c);
  std::vector<uint8_t> back;
  std::string err;
  REQUIRE(inflate_zlib(z.data(), z.size(), data.size(), back, err));
  CHECK(back == data);
  std::vector<uint8_t> exact(data.size());
  REQUIRE(inflate_zlib_exact(z.data(), z.size(), exact.data(), exact.size(), err));
  CHECK(exact == data);
}

TEST_CASE("Inflating a bomb beyond the limit fails before allocating past the limit", "[codecs][deflate]") {
  std::vector<uint8_t> zeros(64 << 20);  // 64 MiB of zeros deflates to ~64 KB
  auto z = deflate_zlib(zeros.data(), zeros.size(), 9);
  zeros = {};
  std::vector<uint8_t> out;
  std::string err;
  CHECK_FALSE(inflate_zlib(z.data(), z.size(), 1 << 20, out, err));
  CHECK(err.find("exceeds the limit of 1048576 bytes") != std::string::npos);
  CHECK(out.capacity() <= (1u << 20));
  std::vector<uint8_t> exact(1000);
  CHECK_FALSE(inflate_zlib_exact(z.data(), z.size(), exact.data(), exact.size(), err));
  CHECK(err.find("exceeds the declared 1000 bytes") != std::string::npos);
}

TEST_CASE("Inflating corrupt, truncated or trailing data fails with a clear error", "[codecs][deflate]") {
  std::vector<uint8_t> data(5000, 42);
  for (size_t i = 0; i < data.size(); i += 3) data[i] = uint8_t(i);
  auto z = deflate_zlib(data.data(), data.size());
  std::vector<uint8_t> out, exact(data.size());
  std::string err;
  // Every truncation is rejected.
  for (size_t n = 0; n < z.size(); ++n) {
    CHECK_FALSE(inflate_zlib(z.data(), n, 1 << 20, out, err));
    CHECK_FALSE(inflate_zlib_exact(z.data(), n, exact.data(), exact.size(), err));
  }
  CHECK_FALSE(inflate_zlib(z.data(), z.size() / 2, 1 << 20, out, err));
  CHECK(err == "deflate: truncated stream");
  // A bad header.
  auto bad = z;
  bad[0] = 0x12;
  CHECK_FALSE(inflate_zlib(bad.data(), bad.size(), 1 << 20, out, err));
  CHECK(err.find("corrupt") != std::string::npos);
  // A wrong checksum.
  bad = z;
  bad.back() ^= 0xff;
  CHECK_FALSE(inflate_zlib(bad.data(), bad.size(), 1 << 20, out, err));
  CHECK(err.find("corrupt") != std::string::npos);
  // Trailing bytes.
  bad = z;
  bad.push_back(0);
  CHECK_FALSE(inflate_zlib(bad.data(), bad.size(), 1 << 20, out, err));
  CHECK(err.find("after the end") != std::string::npos);
  CHECK_FALSE(inflate_zlib_exact(bad.data(), bad.size(), exact.data(), exact.size(), err));
  // Fewer bytes than declared.
  std::vector<uint8_t> more(data.size() + 1);
  CHECK_FALSE(inflate_zlib_exact(z.data(), z.size(), more.data(), more.size(), err));
  CHECK(err.find("declared") != std::string::npos);
  // Garbage.
  std::vector<uint8_t> junk(300);
  for (size_t i = 0; i < junk.size(); ++i) junk[i] = uint8_t(i * 13 + 5);
  CHECK_FALSE(inflate_zlib(junk.data(), junk.size(), 1 << 20, out, err));
}
