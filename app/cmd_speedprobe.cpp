// `tessera speedprobe`: how steadily this machine runs one thread, before a figure is trusted.
// A fixed unit of work (a dependent chain of floating-point operations, about --unit-ms long)
// is timed over and over for --seconds on the calling thread. Every unit does the same work,
// so on a quiet machine they all take about as long as the fastest: how far the percentiles
// and the 250 ms windows fall below it is how far any timing on this machine can move with
// nothing changed in the code. Prints one JSON line.
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <fstream>
#include <stdexcept>
#include <string>
#include <vector>

#include "app/args.h"
#include "app/command.h"
#include "app/common.h"
#include "renderer/disturbance.h"

namespace tessera::app {
namespace {

const char* kHelp =
    "tessera speedprobe [--seconds S] [--unit-ms U]\n"
    "Times one fixed unit of work (about U ms, default 0.5) back to back for S seconds (default 10)\n"
    "on one thread and prints one JSON line: the fastest unit (best_ms), the percentiles of all\n"
    "units (p10, p50, p90, p99, max), the speed of 250 ms windows against the fastest unit (its\n"
    "minimum, median and maximum: 1 = every unit as fast as the best), the thread's CPU time over\n"
    "the wall time (below 1: the kernel ran something else on this core), the load average before\n"
    "and after, and `steady`: whether the median unit is within 5% of the best and no window\n"
    "runs below 0.9 of it. On a machine that is not steady, a timing moves by about 1 - the\n"
    "slowest window's speed between two runs of the same command whatever the code does.\n";

double seconds_now() {
  return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
}

// The unit: n steps of a dependent multiply-add chain (latency-bound: no memory, no vector
// width, the same on every ISA). The result is returned so that the loop is kept.
double unit(long n, double seed) {
  double s = seed;
  for (long i = 0; i < n; ++i) s = s * 0.9999999 + 1e-9 * double(i & 7);
  return s;
}

std::string loadavg() {
  std::ifstream in("/proc/loadavg");
  std::string a;
  in >> a;
  return a.empty() ? "unknown" : a;
}

int run(const std::vector<std::string>& argv) {
  Args args(argv);
  if (args.flag("--help")) {
    std::fputs(kHelp, stdout);
    return 0;
  }
  const double seconds = args.number("--seconds", 10), unit_ms = args.number("--unit-ms", 0.5);
  args.finish();
  if (!(seconds >= 0.5 && seconds <= 3600)) throw std::invalid_argument("--seconds must be in 0.5..3600");
  if (!(unit_ms >= 0.05 && unit_ms <= 100)) throw std::invalid_argument("--unit-ms must be in 0.05..100");
  const std::string load_before = loadavg();

  // Calibration: the steps of one unit, from the fastest of a few timings of a trial unit.
  double sink = 1.0;
  const long trial = 100000;
  double best_trial = 1e9;
  for (int k = 0; k < 20; ++k) {
    const double t0 = seconds_now();
    sink = unit(trial, sink);
    best_trial = std::min(best_trial, seconds_now() - t0);
  }
  const long steps = std::max(1000L, long(double(trial) * unit_ms * 1e-3 / std::max(best_trial, 1e-9)));

  std::vector<double> units;  // seconds each
  units.reserve(size_t(seconds * 1e3 / unit_ms * 2) + 16);
  const uint64_t cpu0 = thread_cpu_ns();
  const double start = seconds_now();
  for (double now = start; now - start < seconds;) {
    const double t0 = now;
    sink = unit(steps, sink);
    now = seconds_now();
    units.push_back(now - t0);
  }
  const double wall = seconds_now() - start, cpu = double(thread_cpu_ns() - cpu0) * 1e-9;
  const double best = *std::min_element(units.begin(), units.end());
  // Windows of about 250 ms: their speed is best x units / their time.
  std::vector<double> windows;
  double acc = 0;
  size_t count = 0;
  for (double u : units) {
    acc += u;
    ++count;
    if (acc >= 0.25) {
      windows.push_back(best * double(count) / acc);
      acc = 0;
      count = 0;
    }
  }
  const double p50 = percentile(units, 0.5);
  const double w_min = windows.empty() ? 0 : *std::min_element(windows.begin(), windows.end());
  const double w_max = windows.empty() ? 0 : *std::max_element(windows.begin(), windows.end());
  const bool steady = p50 <= 1.05 * best && !windows.empty() && w_min >= 0.9;
  std::printf(
      "{\"speedprobe\": true, \"seconds\": %.2f, \"units\": %zu, \"unit_steps\": %ld, \"best_ms\": %.4f, \"p10_ms\": %.4f, "
      "\"p50_ms\": %.4f, \"p90_ms\": %.4f, \"p99_ms\": %.4f, \"max_ms\": %.4f, \"median_speed\": %.3f, \"windows\": %zu, "
      "\"window_speed_min\": %.3f, \"window_speed_median\": %.3f, \"window_speed_max\": %.3f, \"cpu_over_wall\": %.3f, "
      "\"steady\": %s, \"load_before\": %s, \"load_after\": %s, \"cpu\": %s, \"checksum\": %.3f}\n",
      wall, units.size(), steps, best * 1e3, percentile(units, 0.1) * 1e3, p50 * 1e3, percentile(units, 0.9) * 1e3,
      percentile(units, 0.99) * 1e3, *std::max_element(units.begin(), units.end()) * 1e3, best / p50, windows.size(), w_min,
      median(windows), w_max, wall > 0 ? cpu / wall : 0, steady ? "true" : "false", json_str(load_before).c_str(),
      json_str(loadavg()).c_str(), json_str(cpu_model()).c_str(), sink);
  return 0;
}

const Command reg("speedprobe", "how steadily this machine runs one thread: is it quiet enough to measure on?", run);

}  // namespace
}  // namespace tessera::app
