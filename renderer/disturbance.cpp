#include "renderer/disturbance.h"

#include <algorithm>
#include <stdexcept>

namespace tessera {

namespace {

// Median of v (the mean of the two middle values for an even count); v is reordered.
uint32_t median_of(std::vector<uint32_t>& v) {
  const size_t h = v.size() / 2;
  std::nth_element(v.begin(), v.begin() + ptrdiff_t(h), v.end());
  const uint32_t hi = v[h];
  if (v.size() % 2) return hi;
  const uint32_t lo = *std::max_element(v.begin(), v.begin() + ptrdiff_t(h));
  return uint32_t((uint64_t(lo) + hi) / 2);
}

}  // namespace

uint32_t locate_disturbed(const uint32_t* cost, const size_t* idx, int n, uint64_t gap_ns, uint8_t* marks) {
  if (n <= 0) return 0;
  std::vector<uint32_t> c(static_cast<size_t>(n));
  for (int k = 0; k < n; ++k) c[size_t(k)] = cost[idx[k]];
  std::vector<uint32_t> sorted = c;
  const uint64_t ref = median_of(sorted);
  std::vector<int> order(static_cast<size_t>(n));
  for (int k = 0; k < n; ++k) order[size_t(k)] = k;
  std::sort(order.begin(), order.end(), [&](int a, int b) { return c[size_t(a)] > c[size_t(b)]; });
  uint64_t explained = 0;
  int taken = 0;
  for (int k : order) {
    const uint64_t ck = c[size_t(k)];
    const uint64_t excess = ck > ref ? ck - ref : 0;
    if (excess * 4 < gap_ns || explained * 10 >= gap_ns * 9) break;
    explained += excess;
    ++taken;
  }
  uint32_t newly = 0;
  auto mark = [&](int k) {
    uint8_t& m = marks[idx[k]];
    if (!m) { m = kDisturbed; ++newly; }
  };
  if (explained * 2 < gap_ns) {
    for (int k = 0; k < n; ++k) mark(k);
  } else {
    for (int t = 0; t < taken; ++t) mark(order[size_t(t)]);
  }
  return newly;
}

DisturbanceStats replace_disturbed(CostMap& map, const std::vector<uint8_t>& marks) {
  DisturbanceStats st;
  const int32_t w = map.packets.width(), h = map.packets.height();
  if (marks.size() != map.cost.size() || map.cost.size() != size_t(int64_t(w) * h))
    throw std::invalid_argument("replace_disturbed: marks do not match the cost map");
  size_t disturbed = 0, usable = 0;
  for (uint8_t m : marks) {
    disturbed += m == kDisturbed;
    usable += m == 0;
  }
  if (disturbed == 0 || usable == 0) return st;

  const std::vector<uint32_t> measured = map.cost;
  std::vector<uint32_t> vals;
  uint32_t task_median = 0;
  bool have_task_median = false;
  for (int32_t y = 0; y < h; ++y)
    for (int32_t x = 0; x < w; ++x) {
      const size_t i = size_t(y) * size_t(w) + size_t(x);
      if (marks[i] != kDisturbed) continue;
      uint32_t pred = 0;
      bool found = false;
      for (int32_t r = 1; r <= 4 && !found; ++r) {
        vals.clear();
        for (int32_t yy = std::max(0, y - r); yy <= std::min(h - 1, y + r); ++yy)
          for (int32_t xx = std::max(0, x - r); xx <= std::min(w - 1, x + r); ++xx) {
            const size_t j = size_t(yy) * size_t(w) + size_t(xx);
            if (!marks[j]) vals.push_back(measured[j]);
          }
        if (vals.size() >= 3) { pred = median_of(vals); found = true; }
      }
      if (!found && !vals.empty()) { pred = median_of(vals); found = true; }  // 1-2 in the 9x9 window
      if (!found) {
        if (!have_task_median) {
          std::vector<uint32_t> all;
          all.reserve(usable);
          for (size_t j = 0; j < marks.size(); ++j)
            if (!marks[j]) all.push_back(measured[j]);
          task_median = median_of(all);
          have_task_median = true;
        }
        pred = task_median;
      }
      map.cost[i] = pred;
      ++st.packets;
      if (measured[i] > pred) st.removed_ns += measured[i] - pred;
    }
  return st;
}

}  // namespace tessera
