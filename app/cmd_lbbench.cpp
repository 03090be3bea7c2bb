// `tessera lbbench`: times the static load balancer (SAT generation, SAT wire format, tiling)
// on a synthetic 1280x720 cost map and prints one JSON line per measurement, then a summary.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <random>
#include <string>
#include <thread>
#include <vector>

#include <tbb/global_control.h>
#include <tbb/task_arena.h>

#include "app/command.h"
#include "lb/reproject.h"
#include "lb/sat.h"
#include "lb/tiler.h"

namespace tessera::app {
namespace {

constexpr int32_t kWidth = 1280, kHeight = 720;

std::string cpu_model() {
  std::ifstream in("/proc/cpuinfo");
  std::string line;
  while (std::getline(in, line))
    if (line.rfind("model name", 0) == 0) {
      const auto c = line.find(':');
      if (c != std::string::npos) return line.substr(line.find_first_not_of(" \t", c + 1));
    }
  return "unknown";
}

std::string json_escape(const std::string& s) {
  std::string o;
  for (char c : s) {
    if (c == '"' || c == '\\') o += '\\';
    if (static_cast<unsigned char>(c) >= 0x20) o += c;
  }
  return o;
}

// Synthetic per-packet costs in ns: a cheap sky band, a smoothly varying ground with a few
// expensive regions (geometry, reflections), small hot spots (refraction, alpha-mapped
// leaves) and +-20% noise. Seeded, so every run measures the same map.
CostMap synthetic_cost_map(PacketLayout p, uint64_t seed) {
  const Rect space = packet_space(kWidth, kHeight, p);
  CostMap m{space, std::vector<uint32_t>(size_t(space.area()))};
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(0, 1);
  struct Blob {
    double x, y, r, a;
  };
  std::vector<Blob> blobs, hot;
  for (int i = 0; i < 6; ++i) blobs.push_back({u(rng) * kWidth, (0.3 + 0.7 * u(rng)) * kHeight, 60 + 200 * u(rng), 400 * u(rng)});
  for (int i = 0; i < 25; ++i) hot.push_back({u(rng) * kWidth, (0.3 + 0.7 * u(rng)) * kHeight, 4 + 20 * u(rng), 3000 * u(rng)});
  for (int32_t py = 0; py < space.y1; ++py)
    for (int32_t px = 0; px < space.x1; ++px) {
      const double x = (px + 0.5) * p.w, y = (py + 0.5) * p.h;
      double per_pixel = y < 0.3 * kHeight ? 40 : 250 + 150 * x / kWidth;  // ns per pixel
      for (const Blob& b : blobs) per_pixel += b.a * std::exp(-((x - b.x) * (x - b.x) + (y - b.y) * (y - b.y)) / (b.r * b.r));
      for (const Blob& b : hot)
        if (std::fabs(x - b.x) < b.r && std::fabs(y - b.y) < b.r) per_pixel += b.a;
      per_pixel *= 0.8 + 0.4 * u(rng);
      m.cost[size_t(py) * space.x1 + px] = uint32_t(per_pixel * p.size());
    }
  return m;
}

CostMap sub_map(const CostMap& m, const Rect& r) {
  CostMap s{r, {}};
  s.cost.reserve(size_t(r.area()));
  for (int32_t y = r.y0; y < r.y1; ++y)
    for (int32_t x = r.x0; x < r.x1; ++x) s.cost.push_back(m.at(x, y));
  return s;
}

struct Timing {
  double median_ms, min_ms;
};

template <class F>
Timing time_it(int reps, F&& f) {
  f();  // warm-up
  std::vector<double> ms;
  ms.reserve(size_t(reps));
  for (int i = 0; i < reps; ++i) {
    const auto t0 = std::chrono::steady_clock::now();
    f();
    ms.push_back(std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count());
  }
  std::sort(ms.begin(), ms.end());
  return {ms[ms.size() / 2], ms.front()};
}

// Largest task cost / ideal share (1.0 = perfect) as the SAT array predicts it.
double imbalance(const SatArray& a, const std::vector<Rect>& tasks, const std::vector<double>& coef) {
  double csum = 0, worst = 0;
  for (double c : coef) csum += c;
  for (size_t i = 0; i < tasks.size(); ++i) worst = std::max(worst, a.cost(tasks[i]) / (coef[i] / csum * a.total()));
  return worst;
}

int lbbench(const std::vector<std::string>& args) {
  int threads = int(std::max(1u, std::thread::hardware_concurrency()));
  int reps = 101;
  for (size_t i = 0; i < args.size(); ++i) {
    if ((args[i] == "--threads" || args[i] == "--reps") && i + 1 < args.size()) {
      const int v = std::stoi(args[++i]);
      if (v < 1) throw std::invalid_argument(args[i - 1] + " must be >= 1");
      (args[i - 1] == "--threads" ? threads : reps) = v;
    } else if (args[i] == "--help" || args[i] == "-h") {
      std::printf(
          "usage: tessera lbbench [--threads N] [--reps R]\n"
          "Times SAT generation (1280x720, packets 2x2 and 4x4, 1 and N threads), the SAT wire format,\n"
          "tiling for 2, 8 and 20 nodes (one SAT each) and 50,000 tasks on one SAT (1 and N threads).\n"
          "Prints one JSON line per measurement (median over R reps) and a summary line.\n");
      return 0;
    } else {
      throw std::invalid_argument("unknown option '" + args[i] + "' (try --help)");
    }
  }
  tbb::global_control limit(tbb::global_control::max_allowed_parallelism, size_t(threads));
  std::vector<int> thread_counts{1};
  if (threads > 1) thread_counts.push_back(threads);

  // SAT generation and the wire format.
  for (PacketLayout p : {PacketLayout{2, 2}, PacketLayout{4, 4}}) {
    const CostMap m = synthetic_cost_map(p, 42);
    for (int n : thread_counts) {
      tbb::task_arena arena(n);
      Sat s;
      const Timing t = time_it(reps, [&] { arena.execute([&] { s = Sat::from_cost_map(m); }); });
      std::printf(
          "{\"bench\": \"sat_generation\", \"packet\": \"%dx%d\", \"packets\": [%d, %d], \"threads\": %d, "
          "\"reps\": %d, \"median_ms\": %.4f, \"min_ms\": %.4f, \"kernel_ns\": %llu}\n",
          p.w, p.h, m.packets.x1, m.packets.y1, n, reps, t.median_ms, t.min_ms, (unsigned long long)s.total());
    }
    const Sat s = Sat::from_cost_map_serial(m);
    std::vector<uint8_t> buf;
    const Timing ser = time_it(reps, [&] { s.serialize_into(buf); });
    Sat back;
    const Timing de = time_it(reps, [&] { back = Sat::deserialize(buf); });
    std::printf(
        "{\"bench\": \"sat_serialize\", \"packet\": \"%dx%d\", \"bytes\": %zu, \"threads\": 1, \"reps\": %d, "
        "\"median_ms\": %.4f, \"min_ms\": %.4f}\n",
        p.w, p.h, buf.size(), reps, ser.median_ms, ser.min_ms);
    std::printf(
        "{\"bench\": \"sat_deserialize\", \"packet\": \"%dx%d\", \"bytes\": %zu, \"threads\": 1, \"reps\": %d, "
        "\"median_ms\": %.4f, \"min_ms\": %.4f}\n",
        p.w, p.h, buf.size(), reps, de.median_ms, de.min_ms);
  }

  // Tiling with one SAT per node: last frame's tasks were balanced on the same map.
  const PacketLayout p22{2, 2};
  const CostMap m = synthetic_cost_map(p22, 42);
  SatArray whole(m.packets);
  whole.add(Sat::from_cost_map(m));
  whole.finalize();
  for (int nodes : {2, 8, 20}) {
    const std::vector<double> coef(size_t(nodes), 1.0);
    const auto last = tile(&whole, m.packets, coef);
    SatArray array(m.packets);
    for (const Rect& r : last) array.add(Sat::from_cost_map(sub_map(m, r)));
    array.finalize();
    std::vector<Rect> tasks;
    const Timing t = time_it(reps, [&] { tasks = tile(&array, m.packets, coef); });
    std::printf(
        "{\"bench\": \"tiling\", \"nodes\": %d, \"sats\": %zu, \"packet\": \"2x2\", \"threads\": 1, \"reps\": %d, "
        "\"median_ms\": %.4f, \"min_ms\": %.4f, \"max_cost_over_ideal\": %.5f}\n",
        nodes, array.size(), reps, t.median_ms, t.min_ms, imbalance(array, tasks, coef));
  }

  // 50,000 tasks on one SAT, serial and parallel.
  const std::vector<double> coef50k(50000, 1.0);
  for (int n : thread_counts) {
    TilerOptions opt;
    opt.parallel_min_nodes = n > 1 ? 256 : 0;
    tbb::task_arena arena(n);
    std::vector<Rect> tasks;
    const Timing t = time_it(reps, [&] { arena.execute([&] { tasks = tile(&whole, m.packets, coef50k, opt); }); });
    std::printf(
        "{\"bench\": \"tiling\", \"nodes\": 50000, \"sats\": 1, \"packet\": \"2x2\", \"threads\": %d, \"reps\": %d, "
        "\"median_ms\": %.4f, \"min_ms\": %.4f, \"max_cost_over_ideal\": %.5f}\n",
        n, reps, t.median_ms, t.min_ms, imbalance(whole, tasks, coef50k));
  }

  // The reprojecting tiler's step at 1280x720 (actors/tiler_actor.cpp): the previous frame's
  // SATs of 8 nodes as one cost map, carried into a camera turned by 1 degree (points: a
  // surface at smoothly varying depth below a sky band), one SAT of it, 8 tasks.
  for (const PacketLayout p : {PacketLayout{4, 4}, PacketLayout{4, 2}}) {
    const CostMap cm = synthetic_cost_map(p, 42);
    Camera a;
    a.fov_y = 1.0f;
    Camera b = a;
    b.to_world = Mat4::rotate({0, 1, 0}, 3.14159265f / 180);
    const ViewRays va = ViewRays::of(a, kWidth, kHeight);
    PacketPoints pts{cm.packets, std::vector<float>(size_t(cm.packets.area()) * 4)};
    for (int32_t py = 0; py < cm.packets.y1; ++py)
      for (int32_t px = 0; px < cm.packets.x1; ++px) {
        float* o = &pts.xyzw[(size_t(py) * size_t(cm.packets.x1) + size_t(px)) * 4];
        const Vec3 d = va.direction((float(px) + 0.5f) * float(p.w), (float(py) + 0.5f) * float(p.h));
        const bool sky = py < cm.packets.y1 * 3 / 10;
        const float depth = 10 + 5 * std::sin(0.05f * float(px)) + 3 * std::cos(0.07f * float(py));
        o[0] = sky ? d.x : d.x * depth, o[1] = sky ? d.y : d.y * depth, o[2] = sky ? d.z : d.z * depth, o[3] = sky ? 0 : 1;
      }
    const std::vector<double> coef(8, 1.0);
    SatArray prev(cm.packets);
    {
      SatArray whole8(cm.packets);
      whole8.add(Sat::from_cost_map(cm));
      whole8.finalize();
      for (const Rect& r : tile(&whole8, cm.packets, coef)) prev.add(Sat::from_cost_map(sub_map(cm, r)));
      prev.finalize();
    }
    const ViewRays vb = ViewRays::of(b, kWidth, kHeight);
    ReprojectStats rs;
    CostMap flat;
    const Timing tmap = time_it(reps, [&] { flat = prev.cost_map(); });
    const Timing trep = time_it(reps, [&] { reproject(flat, pts, vb, p, &rs); });
    ReprojectStats bs;
    const Timing tblk = time_it(reps, [&] { reproject_blocks(flat, pts, vb, p, 2, &bs); });
    std::vector<Rect> tasks;
    const Timing tall = time_it(reps, [&] {
      SatArray one(cm.packets);
      one.add(Sat::from_cost_map(reproject(prev.cost_map(), pts, vb, p)));
      one.finalize();
      tasks = tile(&one, cm.packets, coef);
    });
    std::printf(
        "{\"bench\": \"reproject\", \"packet\": \"%dx%d\", \"packets\": %lld, \"turn_deg\": 1, \"threads\": 1, "
        "\"reps\": %d, \"cost_map_ms\": %.4f, \"reproject_ms\": %.4f, \"reproject_blocks2_ms\": %.4f, "
        "\"tiler_step_ms\": %.4f, \"filled\": %lld, \"cut\": %s}\n",
        p.w, p.h, (long long)cm.packets.area(), reps, tmap.median_ms, trep.median_ms, tblk.median_ms, tall.median_ms,
        (long long)rs.filled, rs.cut || bs.cut ? "true" : "false");
  }

  std::printf(
      "{\"summary\": true, \"cpu\": \"%s\", \"hardware_threads\": %u, \"threads\": %d, \"reps\": %d, "
      "\"image\": [%d, %d], \"cost_map\": \"synthetic seed 42\", \"statistic\": \"median\"}\n",
      json_escape(cpu_model()).c_str(), std::thread::hardware_concurrency(), threads, reps, kWidth, kHeight);
  return 0;
}

static Command reg("lbbench", "time SAT generation and tiling of the load balancer", lbbench);

}  // namespace
}  // namespace tessera::app
