// Encode times and sizes for a 1280x720 frame: JPEG q75/q85/q95 and DXT1 range/cluster fit
// on 1 and 2 threads. Prints one JSON line per measurement.
//   codecs_bench [repeats] [image.png|jpg ...]
// Images: two synthetic frames, "smooth" (shading with hard edges, like an AO render) and
// "noisy" (the same plus +-6 noise per channel, like a frame with sampling noise; libsquish's
// cluster fit is ~40x slower on it because every block has 16 distinct colours), and any
// files given (tiled or cropped to 1280x720).
#include <tbb/global_control.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstring>
#include <cstdio>
#include <random>
#include <string>
#include <thread>

#include "codecs/dxt1.h"
#include "codecs/jpeg.h"

using namespace tessera;

namespace {

Image synthetic_frame(int w, int h, int amplitude) {
  Image img(w, h);
  std::mt19937 rng(1);
  std::uniform_int_distribution<int> noise(-amplitude, amplitude);
  if (amplitude == 0) noise = std::uniform_int_distribution<int>(0, 0);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      float u = float(x) / w, v = float(y) / h;
      bool box = (x / 160 + y / 120) % 2 == 0;
      float shade = 0.5f + 0.5f * std::sin(3 * u + 2 * v);
      uint8_t* p = img.pixel(x, y);
      p[0] = uint8_t(std::clamp(int(box ? 200 * shade : 60 + 120 * u) + noise(rng), 0, 255));
      p[1] = uint8_t(std::clamp(int(box ? 180 * shade : 90 + 100 * v) + noise(rng), 0, 255));
      p[2] = uint8_t(std::clamp(int(box ? 120 * shade : 150) + noise(rng), 0, 255));
      p[3] = 255;
    }
  return img;
}

template <class F>
double median_ms(int repeats, F&& f) {
  std::vector<double> t;
  f();  // warm up
  for (int i = 0; i < repeats; ++i) {
    auto t0 = std::chrono::steady_clock::now();
    f();
    t.push_back(std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count());
  }
  std::sort(t.begin(), t.end());
  return t[t.size() / 2];
}

void run(const std::string& source, Image img, int repeats) {
  if (img.width != 1280 || img.height != 720) {
    Image f(1280, 720);
    for (int y = 0; y < 720; ++y)
      for (int x = 0; x < 1280; ++x) std::memcpy(f.pixel(x, y), img.pixel(x % img.width, y % img.height), 4);
    img = f;
  }
  JpegEncoder enc;
  std::vector<uint8_t> out;
  std::string err;
  for (int q : {75, 85, 95}) {
    double ms = median_ms(repeats, [&] { enc.encode(img, q, out, err); });
    Image back;
    jpeg_decode(out.data(), out.size(), back, err);
    std::printf("{\"codec\":\"jpeg\",\"quality\":%d,\"threads\":1,\"ms\":%.2f,\"bytes\":%zu,\"psnr\":%.2f,"
                "\"image\":\"%s\",\"size\":\"1280x720\",\"repeats\":%d}\n",
                q, ms, out.size(), compare(img, back).psnr, source.c_str(), repeats);
  }
  for (Dxt1Fit fit : {Dxt1Fit::range, Dxt1Fit::cluster})
    for (int threads : {1, 2}) {
      tbb::global_control c(tbb::global_control::max_allowed_parallelism, threads);
      int n = fit == Dxt1Fit::cluster ? std::max(3, repeats / 3) : repeats;
      double ms = median_ms(n, [&] { dxt1_encode(img, fit, out); });
      double psnr = compare(img, dxt1_decode(out.data(), img.width, img.height)).psnr;
      std::printf("{\"codec\":\"dxt1\",\"fit\":\"%s\",\"threads\":%d,\"ms\":%.2f,\"bytes\":%zu,\"psnr\":%.2f,"
                  "\"image\":\"%s\",\"size\":\"1280x720\",\"repeats\":%d}\n",
                  fit == Dxt1Fit::range ? "range" : "cluster", threads, ms, out.size(), psnr, source.c_str(), n);
    }
}

}  // namespace

int main(int argc, char** argv) {
  int repeats = argc > 1 ? std::stoi(argv[1]) : 15;
  run("smooth", synthetic_frame(1280, 720, 0), repeats);
  run("noisy", synthetic_frame(1280, 720, 6), repeats);
  for (int i = 2; i < argc; ++i) run(argv[i], read_image(argv[i]), repeats);
  std::printf("{\"summary\":true,\"hardware_threads\":%u,\"jpeg\":\"libjpeg-turbo 4:2:0\",\"dxt1\":\"libsquish per block, TBB over block rows\"}\n",
              std::thread::hardware_concurrency());
  return 0;
}
