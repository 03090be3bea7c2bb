// Cost maps that ignore disturbances (renderer/disturbance.h, docs/load-balancing.md):
// locating the packets of a disturbed sub-block, replacing their cost from undisturbed
// neighbours, and an injected stall (RenderSettings::stall_us) in a real render, found,
// replaced, and without effect on the load balancer's tiling.
#include <catch2/catch.hpp>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <string>
#include <vector>

#include "core/gltf_loader.h"
#include "lb/sat.h"
#include "lb/tiler.h"
#include "renderer/disturbance.h"
#include "renderer/raytracer.h"

using namespace tessera;

namespace {

// A smooth synthetic map: cost grows with x and y, 10-40 us per packet.
CostMap synthetic(Rect packets) {
  CostMap m;
  m.packets = packets;
  for (int32_t y = packets.y0; y < packets.y1; ++y)
    for (int32_t x = packets.x0; x < packets.x1; ++x) m.cost.push_back(uint32_t(10000 + 1000 * x + 500 * y));
  return m;
}

size_t at(const CostMap& m, int32_t x, int32_t y) {
  return size_t(y - m.packets.y0) * size_t(m.packets.width()) + size_t(x - m.packets.x0);
}

uint32_t median(std::vector<uint32_t> v) {
  std::sort(v.begin(), v.end());
  return v.size() % 2 ? v[v.size() / 2] : uint32_t((uint64_t(v[v.size() / 2 - 1]) + v[v.size() / 2]) / 2);
}

// Median of the (up to 8) neighbours of packet (x, y).
uint32_t neighbour_median(const CostMap& m, int32_t x, int32_t y) {
  std::vector<uint32_t> v;
  for (int32_t yy = y - 1; yy <= y + 1; ++yy)
    for (int32_t xx = x - 1; xx <= x + 1; ++xx)
      if ((xx != x || yy != y) && m.packets.contains(xx, yy)) v.push_back(m.cost[at(m, xx, yy)]);
  return median(v);
}

// The worst relative deviation of a task's cost, measured on `truth`, from its equal share.
double imbalance(const std::vector<Rect>& tasks, const CostMap& truth) {
  const Sat sat = Sat::from_cost_map(truth);
  const double share = double(sat.total()) / double(tasks.size());
  double worst = 0;
  for (const Rect& t : tasks) worst = std::max(worst, std::fabs(double(sat.cost(t)) / share - 1.0));
  return worst;
}

std::vector<Rect> tiling(const CostMap& map, int nodes) {
  SatArray sats(map.packets);
  sats.add(Sat::from_cost_map(map));
  sats.finalize();
  return tile(&sats, map.packets, std::vector<double>(size_t(nodes), 1.0));
}

}  // namespace

TEST_CASE("locate_disturbed: the packet that absorbed the gap, or the whole sub-block") {
  std::vector<uint32_t> cost(64);
  for (size_t i = 0; i < cost.size(); ++i) cost[i] = uint32_t(3000 + 37 * (i % 7));
  std::vector<size_t> idx(32);
  for (size_t k = 0; k < idx.size(); ++k) idx[k] = 10 + k;  // a sub-block inside the map

  SECTION("one stalled packet") {
    cost[20] += 5000000;
    std::vector<uint8_t> marks(cost.size(), 0);
    CHECK(locate_disturbed(cost.data(), idx.data(), 32, 5000000, marks.data()) == 1);
    for (size_t i = 0; i < marks.size(); ++i) CHECK(int(marks[i]) == (i == 20 ? 1 : 0));
  }
  SECTION("two stalls of 100 us") {
    cost[12] += 100000;
    cost[30] += 100000;
    std::vector<uint8_t> marks(cost.size(), 0);
    CHECK(locate_disturbed(cost.data(), idx.data(), 32, 200000, marks.data()) == 2);
    CHECK(marks[12] == 1);
    CHECK(marks[30] == 1);
  }
  SECTION("a stall spread over the sub-block: every packet is marked") {
    for (size_t k = 10; k < 42; ++k) cost[k] += 3000;  // 96 us over 32 packets
    std::vector<uint8_t> marks(cost.size(), 0);
    CHECK(locate_disturbed(cost.data(), idx.data(), 32, 96000, marks.data()) == 32);
    for (size_t i = 0; i < marks.size(); ++i) CHECK(int(marks[i]) == (i >= 10 && i < 42 ? 1 : 0));
  }
}

TEST_CASE("replace_disturbed on a synthetic map") {
  const Rect packets{4, 2, 24, 14};
  const CostMap clean = synthetic(packets);
  CostMap m = clean;
  std::vector<uint8_t> marks(m.cost.size(), 0);
  auto stall = [&](int32_t x, int32_t y, uint32_t ns) {
    m.cost[at(m, x, y)] += ns;
    marks[at(m, x, y)] = 1;
  };
  stall(10, 6, 5000000);  // interior
  stall(4, 2, 5000000);   // corner
  for (int32_t y = 8; y < 13; ++y)  // a 5x5 patch: the middle needs the 9x9 window
    for (int32_t x = 14; x < 19; ++x) stall(x, y, 200000);
  const DisturbanceStats st = replace_disturbed(m, marks);
  CHECK(st.packets == 27);
  CHECK(st.removed_ns > 10000000);
  for (size_t i = 0; i < m.cost.size(); ++i) {
    if (!marks[i]) {
      CHECK(m.cost[i] == clean.cost[i]);  // measured costs are kept exactly
    } else {
      // The map is linear: a neighbourhood median is within a few packets' slope of the truth.
      INFO("packet " << i << ": " << m.cost[i] << " vs " << clean.cost[i]);
      CHECK(std::fabs(double(m.cost[i]) - double(clean.cost[i])) <= 0.15 * clean.cost[i]);
    }
  }
  // The interior packet: exactly the median of its 8 (all undisturbed) neighbours.
  CHECK(m.cost[at(m, 10, 6)] == neighbour_median(clean, 10, 6));

  SECTION("every packet marked: nothing to predict from, nothing changes") {
    CostMap all = clean;
    const DisturbanceStats none = replace_disturbed(all, std::vector<uint8_t>(all.cost.size(), 1));
    CHECK(none.packets == 0);
    CHECK(all.cost == clean.cost);
  }
  SECTION("one undisturbed packet left: the task median fallback") {
    CostMap one = synthetic({0, 0, 12, 12});
    std::vector<uint8_t> mk(one.cost.size(), 1);
    mk[0] = 0;
    const uint32_t keep = one.cost[0];
    CHECK(replace_disturbed(one, mk).packets == 143);
    for (uint32_t c : one.cost) CHECK(c == keep);
  }
  SECTION("packets an adaptive round did not render (cost 0) are neither used nor replaced") {
    CostMap part = clean;
    std::vector<uint8_t> mk(part.cost.size(), 0);
    // Around (10, 6): its left column not rendered, itself disturbed.
    for (int32_t y = 5; y <= 7; ++y) {
      part.cost[at(part, 9, y)] = 0;
      mk[at(part, 9, y)] = kNotRendered;
    }
    part.cost[at(part, 10, 6)] += 5000000;
    mk[at(part, 10, 6)] = kDisturbed;
    CHECK(replace_disturbed(part, mk).packets == 1);
    for (int32_t y = 5; y <= 7; ++y) CHECK(part.cost[at(part, 9, y)] == 0);
    std::vector<uint32_t> five;  // its 5 rendered neighbours
    for (int32_t y = 5; y <= 7; ++y)
      for (int32_t x = 10; x <= 11; ++x)
        if (!(x == 10 && y == 6)) five.push_back(clean.cost[at(clean, x, y)]);
    std::sort(five.begin(), five.end());
    CHECK(part.cost[at(part, 10, 6)] == five[2]);
    // Nothing rendered but the disturbed packet: nothing to predict from.
    CostMap lone = clean;
    std::vector<uint8_t> only(lone.cost.size(), kNotRendered);
    only[0] = kDisturbed;
    CHECK(replace_disturbed(lone, only).packets == 0);
    CHECK(lone.cost == clean.cost);
  }
  SECTION("marks of the wrong size are refused") {
    CostMap x = clean;
    CHECK_THROWS_AS(replace_disturbed(x, std::vector<uint8_t>(3, 0)), std::invalid_argument);
  }
}

TEST_CASE("an injected 5 ms stall is detected, replaced and does not move the tiling") {
  const std::string dir = std::string(TESSERA_SCENES_DIR) + "/pavilion";
  LoadedScene ls = load_gltf(dir + "/scene.gltf");
  CameraLoop loop = load_camera_loop(dir + "/camera-loop.json");
  ls.scene.set_camera(loop.camera(0));
  const int32_t W = 320, H = 180;
  ls.scene.set_resolution(W, H);
  RayTracer rt;
  std::vector<std::string> warnings;
  rt.sync(ls.scene, warnings);
  RenderSettings s;
  s.ao_samples = 2;
  const Rect full{0, 0, W, H};
  TaskResult warm, ref, stalled, raw;
  rt.render(full, s, warm);  // first touch of the scene's data
  rt.render(full, s, ref);
  const PacketLayout pl = rt.packet_layout();
  RenderSettings st = s;
  st.stall_px = W / pl.w / 2;
  st.stall_py = H / pl.h / 2;
  st.stall_us = 5000;
  rt.render(full, st, stalled);
  RenderSettings off = st;
  off.disturbance_check = false;
  rt.render(full, off, raw);

  const size_t n = ref.cost.cost.size();
  const size_t p = at(stalled.cost, st.stall_px, st.stall_py);
  INFO("packets " << n << ", kernel_ms ref " << ref.kernel_ms << " stalled " << stalled.kernel_ms << " raw " << raw.kernel_ms
                  << "; disturbed: ref " << ref.disturbed_packets << " (" << ref.disturbed_ns << " ns), stalled "
                  << stalled.disturbed_packets << " (" << stalled.disturbed_ns << " ns); stalled packet " << stalled.cost.cost[p]
                  << " ns (raw " << raw.cost.cost[p] << ", ref " << ref.cost.cost[p] << ", neighbours "
                  << neighbour_median(stalled.cost, st.stall_px, st.stall_py) << ")");
  // Without a stall, replacements are what the machine's own preemptions cause: a few on a
  // quiet machine, 5% of the packets under ASan beside a sanitizer build on 2 cores, 26% once
  // in the Release suite with another test on the second core (938 of 3600; the two render
  // threads were preempted through much of the frame). A detector that flagged every
  // sub-block (a clock or unit mix-up) would pass far above this.
  CHECK(ref.disturbed_packets <= n / 2);
  // Without the check, the stall is in the map; with it, it is found and replaced.
  CHECK(raw.disturbed_packets == 0);
  CHECK(raw.cost.cost[p] >= 5000000);
  CHECK(stalled.disturbed_packets >= 1);
  CHECK(stalled.disturbed_ns >= 4500000);
  const double nb = neighbour_median(stalled.cost, st.stall_px, st.stall_py);
  CHECK(stalled.cost.cost[p] < 5000000);  // less than the stall alone (ASan packets take ~1 ms)
  CHECK(stalled.cost.cost[p] <= 3 * nb);
  CHECK(stalled.cost.cost[p] * 3 >= nb);

  // The tiling. Two renders of a frame on a shared machine differ by far more than one packet
  // (contention and frequency changes that are not stalls: the thread runs, slower), so the
  // tiling is compared on one map, the per-packet minimum of 3 undisturbed renders: with the
  // stall added to the stalled packet (what the raw map held, at least 5% of the frame's cost,
  // so that it steers the tiling also where packets are slow, as under ASan), and with that
  // packet replaced as the renderer replaced it above. The cleaned map's tiling must balance the undisturbed
  // costs as well as the undisturbed map's own tiling, within 2% of a task's share or a packet line; the raw
  // map's must be visibly worse.
  CostMap ref_min = ref.cost;
  for (int i = 1; i < 3; ++i) {
    TaskResult r;
    rt.render(full, s, r);
    REQUIRE(r.cost.cost.size() == ref_min.cost.size());
    for (size_t j = 0; j < ref_min.cost.size(); ++j) ref_min.cost[j] = std::min(ref_min.cost[j], r.cost.cost[j]);
  }
  CostMap raw_min = ref_min;
  raw_min.cost[p] += uint32_t(std::max<uint64_t>(raw.cost.cost[p], ref_min.total() / 20));
  CostMap clean_min = raw_min;
  std::vector<uint8_t> marks(clean_min.cost.size(), 0);
  marks[p] = 1;
  replace_disturbed(clean_min, marks);
  CHECK(raw_min.cost[p] >= 5000000);
  CHECK(clean_min.cost[p] <= 3 * nb);
  for (int nodes : {2, 8}) {
    const double imb_ref = imbalance(tiling(ref_min, nodes), ref_min);
    const double imb_clean = imbalance(tiling(clean_min, nodes), ref_min);
    const double imb_raw = imbalance(tiling(raw_min, nodes), ref_min);
    INFO(nodes << " nodes: worst task off its share by " << imb_ref << " (undisturbed tiling), " << imb_clean
               << " (cleaned), " << imb_raw << " (raw)");
    // One packet's cost moved (the replacement is a neighbour's, not the packet's own) can move a
    // split by a whole packet line, about sqrt(nodes / packets) of a task's share (0.047 at 8
    // nodes here): the bound is that or 2%, whichever is larger.
    const double line = std::sqrt(double(nodes) / double(n));
    CHECK(imb_clean <= imb_ref + std::max(0.02, line));
    CHECK(imb_raw > imb_clean + 0.02);
  }
}
