// The balancer's reprojection (lb/reproject.h) against brute force: a wall with an occluder in
// front, rendered by the ray tracer with hit points; the previous frame's cost map carried
// into a moved camera is checked, target packet by target packet, against what casting every
// pixel of that packet in the new view and projecting its hit back into the old view says.
#include <catch2/catch.hpp>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <set>
#include <utility>

#include "lb/reproject.h"
#include "lb/tiler.h"
#include "scene_builders.h"

using namespace tessera;
using namespace tessera::testing;

namespace {

constexpr int W = 256, H = 144;
constexpr float kFov = 1.0471976f;  // 60 degrees
constexpr float kWallZ = -20, kOccZ = -8, kOccHalf = 1.5f;

// What the pixel ray from eye along d hits first: 2 the occluder, 1 the wall, 0 nothing.
int hit(Vec3 eye, Vec3 d, Vec3& p) {
  if (d.z < 0) {
    const float t = (kOccZ - eye.z) / d.z;
    const Vec3 q = eye + d * t;
    if (std::fabs(q.x) <= kOccHalf && std::fabs(q.y) <= kOccHalf) {
      p = q;
      return 2;
    }
    const float tw = (kWallZ - eye.z) / d.z;
    p = eye + d * tw;
    return std::fabs(p.x) <= 40 && std::fabs(p.y) <= 40 ? 1 : 0;
  }
  return 0;
}

struct Frame {
  Camera cam;
  TaskResult r;
  PacketLayout layout;
};

Frame render_view(const Camera& cam) {
  Scene scene;
  scene.set_resolution(W, H);
  scene.set_environment(plain_env({0.2f, 0.3f, 0.9f}, {0.5f, 0.5f, 0.5f}));
  scene.set_material(1, diffuse({0.8f, 0.8f, 0.8f}));
  scene.set_material(2, diffuse({0.9f, 0.2f, 0.1f}));
  add_object(scene, 10, quad({-40, -40, kWallZ}, {80, 0, 0}, {0, 80, 0}), 1);
  add_object(scene, 20, quad({-kOccHalf, -kOccHalf, kOccZ}, {2 * kOccHalf, 0, 0}, {0, 2 * kOccHalf, 0}), 2);
  scene.set_light(1, directional({0.2f, -1, -0.3f}));
  scene.set_camera(cam);
  RayTracer rt;
  RenderSettings s = no_ao(1);
  s.hit_points = true;
  Frame f{cam, {}, rt.packet_layout()};
  render_full(rt, scene, s, nullptr, &f.r);
  return f;
}

// The surface a packet of the old frame saw (its centre pixel), for costs by surface.
int surface_of(const Frame& f, int32_t px, int32_t py) {
  const int x = std::min(px * f.layout.w + f.layout.w / 2, W - 1), y = std::min(py * f.layout.h + f.layout.h / 2, H - 1);
  Vec3 p;
  return hit(cam_pos(f.cam), pixel_dir(f.cam, W, H, float(x), float(y)), p);
}

// Whether the old frame's packet saw both surfaces (the occluder's outline): its hit point is
// a mean of the two, in mid-air.
bool mixed(const Frame& f, int32_t px, int32_t py) {
  int seen = 0;
  for (int y = py * f.layout.h; y < std::min((py + 1) * f.layout.h, H); ++y)
    for (int x = px * f.layout.w; x < std::min((px + 1) * f.layout.w, W); ++x) {
      Vec3 p;
      seen |= hit(cam_pos(f.cam), pixel_dir(f.cam, W, H, float(x), float(y)), p);
    }
  return seen == 3;
}

// Brute force for target packet (tx, ty) of view `to`: the old frame's packets its pixels'
// hits project into (`sources`), and whether some pixel sees a point the old view did not
// see (disoccluded) or that lies outside the old image.
struct Truth {
  std::set<std::pair<int32_t, int32_t>> sources;
  int surfaces = 0;  // bit 1: some pixel sees the wall, bit 2: the occluder
  bool unseen = false;
  double mean_x = 0, mean_y = 0;  // the mean old pixel position (pixel centres) of its pixels
};

Truth brute_force(const Frame& from, const Camera& to, PacketLayout layout, int32_t tx, int32_t ty) {
  Truth t;
  int seen = 0;
  for (int y = ty * layout.h; y < std::min((ty + 1) * layout.h, H); ++y)
    for (int x = tx * layout.w; x < std::min((tx + 1) * layout.w, W); ++x) {
      Vec3 p;
      const int s = hit(cam_pos(to), pixel_dir(to, W, H, float(x), float(y)), p);
      if (s == 0) {
        t.unseen = true;
        continue;
      }
      t.surfaces |= s;
      float ox, oy;
      project(from.cam, W, H, p, ox, oy);
      const int sx = int(std::floor(ox + 0.5f)), sy = int(std::floor(oy + 0.5f));
      if (sx < 0 || sy < 0 || sx >= W || sy >= H) {
        t.unseen = true;
        continue;
      }
      Vec3 q;  // does the old view see this point there, or something nearer?
      const int s_old = hit(cam_pos(from.cam), pixel_dir(from.cam, W, H, float(sx), float(sy)), q);
      if (s_old != s) t.unseen = true;
      t.sources.insert({sx / layout.w, sy / layout.h});
      t.mean_x += ox + 0.5;
      t.mean_y += oy + 0.5;
      ++seen;
    }
  if (seen > 0) {
    t.mean_x /= seen;
    t.mean_y /= seen;
  }
  return t;
}

// Costs that encode the old packet's x: 1000 + 100 x.
CostMap x_costs(const Frame& f) {
  CostMap m = f.r.cost;
  for (int32_t py = 0; py < m.packets.y1; ++py)
    for (int32_t px = 0; px < m.packets.x1; ++px) m.cost[size_t(py) * m.packets.x1 + px] = uint32_t(1000 + 100 * px);
  return m;
}

// Of the packets of `moved` (x_costs carried from frame a into camera b) that see the wall in
// both views: how many, and how many read an old x within `tolerance` packets of where their
// pixels really come from (the brute force).
std::pair<int, int> wall_packets_near(const CostMap& moved, const Frame& a, const Camera& b, double tolerance) {
  int checked = 0, close = 0;
  for (int32_t ty = 0; ty < moved.packets.y1; ++ty)
    for (int32_t tx = 0; tx < moved.packets.x1; ++tx) {
      const Truth t = brute_force(a, b, a.layout, tx, ty);
      if (t.unseen || t.surfaces != 1) continue;
      ++checked;
      close += std::fabs((double(moved.at(tx, ty)) - 1000) / 100 - (t.mean_x / a.layout.w - 0.5)) <= tolerance;
    }
  return {checked, close};
}

// Every packet a cost of its own, so a value names the packet it came from.
CostMap distinct_costs(const Frame& f) {
  CostMap m = f.r.cost;
  for (size_t i = 0; i < m.cost.size(); ++i) m.cost[i] = uint32_t(1000 + 7 * i);
  return m;
}

}  // namespace

TEST_CASE("The renderer's hit points put each packet back where it was", "[reproject]") {
  const Frame a = render_view(look({0, 0, 0}, {0, 0, -1}, kFov));
  REQUIRE(a.r.points.packets == a.r.cost.packets);
  REQUIRE(a.r.points.xyzw.size() == a.r.cost.cost.size() * 4);
  const CostMap cost = distinct_costs(a);
  ReprojectStats st;
  const CostMap same = reproject(cost, a.r.points, ViewRays::of(a.cam, W, H), a.layout, &st);
  CHECK_FALSE(st.cut);
  CHECK(st.splatted == st.packets);
  // Every packet keeps its own cost, except on the occluder's outline: there a packet's point
  // is the mean of its foreground rays' hits, off its centre, so its footprint is shared with a
  // neighbour.
  int same_cost = 0;
  for (size_t i = 0; i < cost.cost.size(); ++i) {
    const int32_t px = int32_t(i % size_t(cost.packets.width())), py = int32_t(i / size_t(cost.packets.width()));
    if (same.cost[i] == cost.cost[i]) {
      ++same_cost;
      continue;
    }
    bool near_outline = false;  // it, or a neighbour whose footprint reaches into it
    for (int32_t dy = -1; dy <= 1; ++dy)
      for (int32_t dx = -1; dx <= 1; ++dx) near_outline = near_outline || mixed(a, px + dx, py + dy);
    CHECK(near_outline);
  }
  CHECK(same_cost > int(cost.cost.size()) * 9 / 10);
  // Hit points lie on the surfaces (the foreground one for a packet on an outline), w = 1
  // everywhere here.
  for (size_t i = 0; i < cost.cost.size(); ++i) {
    const float* p = &a.r.points.xyzw[i * 4];
    REQUIRE(p[3] == 1);
    REQUIRE((std::fabs(p[2] - kWallZ) < 1e-3f || std::fabs(p[2] - kOccZ) < 1e-3f));
  }
}

TEST_CASE("A sideways move of exactly two packets on the wall shifts its costs by two packets", "[reproject]") {
  const Frame a = render_view(look({0, 0, 0}, {0, 0, -1}, kFov));
  // One pixel on the wall (depth 20) is 2 * 20 * tan(fov/2) / H world units.
  const float pixel = 2 * 20 * std::tan(kFov / 2) / float(H);
  const float dx = 2 * float(a.layout.w) * pixel;
  const Camera b = look({dx, 0, 0}, {dx, 0, -1}, kFov);
  const CostMap cost = distinct_costs(a);
  ReprojectStats st;
  const CostMap moved = reproject(cost, a.r.points, ViewRays::of(b, W, H), a.layout, &st);
  CHECK_FALSE(st.cut);
  int checked = 0, wrong = 0;
  for (int32_t ty = 0; ty < moved.packets.y1; ++ty)
    for (int32_t tx = 0; tx < moved.packets.x1; ++tx) {
      const Truth t = brute_force(a, b, a.layout, tx, ty);
      if (t.unseen || t.sources.size() != 1 || t.surfaces != 1) continue;
      const auto [sx, sy] = *t.sources.begin();
      CHECK(sx == tx + 2);  // the brute force agrees with the geometry of the move
      ++checked;
      if (moved.at(tx, ty) != cost.at(sx, sy)) ++wrong;
    }
  INFO(checked << " wall packets checked, " << wrong << " wrong");
  CHECK(checked > moved.packets.area() / 2);
  CHECK(wrong == 0);
}

TEST_CASE("A turn lands each packet's cost where the geometry says", "[reproject]") {
  const Frame a = render_view(look({0, 0, 0}, {0, 0, -1}, kFov));
  const float yaw = 4 * kPi / 180;
  const Camera b = look({0, 0, 0}, {std::sin(yaw), 0.02f, -std::cos(yaw)}, kFov);
  // Costs that say where they came from: 1000 + 100 x (the old packet's x), then the same in y.
  // Bilinear footprints blend neighbouring packets, and a blend of a linear function is the
  // function at the blended position: the carried cost reads back as a position in the old
  // frame, to compare with where the new packet's pixels really come from.
  for (int axis = 0; axis < 2; ++axis) {
    CostMap cost = a.r.cost;
    for (int32_t py = 0; py < cost.packets.y1; ++py)
      for (int32_t px = 0; px < cost.packets.x1; ++px)
        cost.cost[size_t(py) * cost.packets.x1 + px] = uint32_t(1000 + 100 * (axis == 0 ? px : py));
    ReprojectStats st;
    const CostMap moved = reproject(cost, a.r.points, ViewRays::of(b, W, H), a.layout, &st);
    CHECK_FALSE(st.cut);
    int checked = 0, close = 0;
    double worst = 0;
    for (int32_t ty = 0; ty < moved.packets.y1; ++ty)
      for (int32_t tx = 0; tx < moved.packets.x1; ++tx) {
        const Truth t = brute_force(a, b, a.layout, tx, ty);
        if (t.unseen || t.surfaces != 1) continue;  // the wall, seen in both views
        ++checked;
        const double carried = (double(moved.at(tx, ty)) - 1000) / 100;  // packet coordinate
        const double truth = axis == 0 ? t.mean_x / a.layout.w - 0.5 : t.mean_y / a.layout.h - 0.5;
        worst = std::max(worst, std::fabs(carried - truth));
        close += std::fabs(carried - truth) <= 0.35;
      }
    INFO("axis " << axis << ": " << checked << " wall packets checked, " << close
                 << " carried from within 0.35 packets of where their pixels come from; worst " << worst << "; "
                 << st.filled << " filled");
    CHECK(checked > moved.packets.area() * 6 / 10);
    CHECK(close >= checked * 95 / 100);
    CHECK(worst < 1.5);
  }
}

TEST_CASE("The nearer surface wins, and what the move uncovered is filled from neighbours", "[reproject]") {
  const Frame a = render_view(look({0, 0, 0}, {0, 0, -1}, kFov));
  const Camera b = look({1.2f, 0.3f, 0}, {1.2f, 0.3f, -1}, kFov);  // the occluder slides over the wall
  CostMap cost = a.r.cost;
  for (int32_t py = 0; py < cost.packets.y1; ++py)
    for (int32_t px = 0; px < cost.packets.x1; ++px)
      cost.cost[size_t(py) * cost.packets.x1 + px] = surface_of(a, px, py) == 2 ? 9000 : 1000;
  ReprojectStats st;
  const CostMap moved = reproject(cost, a.r.points, ViewRays::of(b, W, H), a.layout, &st);
  CHECK_FALSE(st.cut);
  int occluder = 0, wall = 0, uncovered = 0;
  const int32_t PW = moved.packets.x1, PH = moved.packets.y1;
  std::vector<Truth> truth;
  for (int32_t ty = 0; ty < PH; ++ty)
    for (int32_t tx = 0; tx < PW; ++tx) truth.push_back(brute_force(a, b, a.layout, tx, ty));
  // Beside what the move uncovered a packet may be only partly covered by footprints, and then
  // it is filled from its neighbours like the uncovered ones.
  auto beside_uncovered = [&](int32_t tx, int32_t ty) {
    for (int32_t dy = -1; dy <= 1; ++dy)
      for (int32_t dx = -1; dx <= 1; ++dx) {
        const int32_t x = tx + dx, y = ty + dy;
        if (x >= 0 && y >= 0 && x < PW && y < PH && truth[size_t(y) * PW + x].unseen) return true;
      }
    return false;
  };
  for (int32_t ty = 0; ty < PH; ++ty)
    for (int32_t tx = 0; tx < PW; ++tx) {
      const Truth& t = truth[size_t(ty) * PW + tx];
      const uint32_t v = moved.at(tx, ty);
      bool outline = false;  // a source on the occluder's outline: its point is a mean in mid-air
      for (auto [sx, sy] : t.sources) outline = outline || mixed(a, sx, sy);
      if (t.surfaces == 2 && !t.unseen) {  // all of it sees the occluder, which the old view saw
        if (outline) continue;
        ++occluder;
        INFO("occluder packet " << tx << "," << ty);
        CHECK(v == 9000);  // not the wall behind it, whose points land here too
      } else if (t.surfaces == 1 && !t.unseen) {
        // Footprints are a packet wide: beside the occluder's image (in the new view), its
        // outline packets spread a share of it into this one.
        bool next_to_occluder = false;
        for (int32_t dy = -1; dy <= 1; ++dy)
          for (int32_t dx = -1; dx <= 1; ++dx) {
            const int32_t x = tx + dx, y = ty + dy;
            if (x >= 0 && y >= 0 && x < PW && y < PH) next_to_occluder = next_to_occluder || (truth[size_t(y) * PW + x].surfaces & 2);
          }
        if (next_to_occluder || beside_uncovered(tx, ty)) continue;
        ++wall;
        INFO("wall packet " << tx << "," << ty);
        CHECK(v == 1000);
      } else if (t.surfaces == 1 && t.unseen) {
        ++uncovered;
        CHECK(v >= 1000);
        CHECK(v <= 9000);
      }
    }
  INFO(occluder << " occluder, " << wall << " wall, " << uncovered << " uncovered packets; " << st.filled << " filled");
  CHECK(occluder > 20);
  CHECK(wall > moved.packets.area() / 2);
  CHECK(uncovered > 0);
  CHECK(st.filled >= 1);
  CHECK(st.kept == 0);
}

TEST_CASE("A cut gives the unprojected map back, and the tiling from it is sound", "[reproject]") {
  const Frame a = render_view(look({0, 0, 0}, {0, 0, -1}, kFov));
  const Camera back = look({0, 0, 0}, {0, 0, 1}, kFov);  // turned round: nothing of the old view
  const CostMap cost = distinct_costs(a);
  ReprojectStats st;
  const CostMap m = reproject(cost, a.r.points, ViewRays::of(back, W, H), a.layout, &st);
  CHECK(st.cut);
  CHECK(st.splatted == 0);
  CHECK(m.cost == cost.cost);
  SatArray sats(m.packets);
  sats.add(Sat::from_cost_map(m));
  sats.finalize();
  const auto tasks = tile(&sats, m.packets, std::vector<double>(8, 1.0));
  int64_t area = 0;
  for (const Rect& r : tasks) {
    CHECK_FALSE(r.empty());
    area += r.area();
  }
  CHECK(area == m.packets.area());
  // Without hit points (a renderer that gives none) the map also comes back as it was.
  ReprojectStats none;
  CHECK(reproject(cost, PacketPoints{}, ViewRays::of(a.cam, W, H), a.layout, &none).cost == cost.cost);
  CHECK(none.cut);
}

TEST_CASE("Depths on the wire put each packet's point back on its ray, and any float is safe", "[reproject]") {
  const Frame a = render_view(look({0, 0, 0}, {0, 0, -1}, kFov));
  const ViewRays va = ViewRays::of(a.cam, W, H);
  const std::vector<uint8_t> wire = encode_depths(a.r.points, va);
  REQUIRE(wire.size() == a.r.cost.cost.size() * 4);
  const Rect space = a.r.cost.packets;
  PacketPoints back{space, std::vector<float>(size_t(space.area()) * 4, -1.0f)};
  REQUIRE(decode_depths(wire.data(), wire.size(), space, va, a.layout, back));
  // Each decoded point projects to its packet's centre at the depth the exact point had.
  for (int32_t py = space.y0; py < space.y1; ++py)
    for (int32_t px = space.x0; px < space.x1; ++px) {
      const size_t i = size_t(py) * size_t(space.width()) + size_t(px);
      const float* p = &a.r.points.xyzw[i * 4];
      const float* q = &back.xyzw[i * 4];
      REQUIRE(q[3] == p[3]);
      float x0, y0, d0, x1, y1, d1;
      REQUIRE(va.project(p, x0, y0, d0));
      REQUIRE(va.project(q, x1, y1, d1));
      CHECK(std::fabs(d1 - d0) <= 1e-4f * d0);
      CHECK(std::fabs(x1 - (float(px) + 0.5f) * float(a.layout.w)) < 1e-2f);
      CHECK(std::fabs(y1 - (float(py) + 0.5f) * float(a.layout.h)) < 1e-2f);
    }
  // Carried through a turn from the decoded points, the map is the exact points' map but for
  // sub-packet shifts: within 0.5 packets of where the geometry says (the linear costs of the
  // turn test above).
  const float yaw = 4 * kPi / 180;
  const Camera b = look({0, 0, 0}, {std::sin(yaw), 0.02f, -std::cos(yaw)}, kFov);
  const CostMap cost = x_costs(a);
  ReprojectStats st;
  const CostMap moved = reproject(cost, back, ViewRays::of(b, W, H), a.layout, &st);
  CHECK_FALSE(st.cut);
  const auto [checked, close] = wall_packets_near(moved, a, b, 0.5);
  INFO(checked << " wall packets, " << close << " within 0.5 packets");
  CHECK(checked > moved.packets.area() * 6 / 10);
  CHECK(close >= checked * 95 / 100);

  // Hostile or broken depths: negative, zero, NaN, -inf and huge values give "nothing known" or
  // a far point, +inf the sky; a wrong size or a rectangle outside the map writes nothing.
  const float odd[] = {-1.0f, 0.0f, std::numeric_limits<float>::quiet_NaN(), -std::numeric_limits<float>::infinity(),
                       3.4e38f, std::numeric_limits<float>::infinity(), 1e-30f, 7.0f};
  const Rect row{0, 0, 8, 1};
  std::vector<uint8_t> bytes(sizeof odd);
  std::memcpy(bytes.data(), odd, sizeof odd);
  PacketPoints into{space, std::vector<float>(size_t(space.area()) * 4, -1.0f)};
  REQUIRE(decode_depths(bytes.data(), bytes.size(), row, va, a.layout, into));
  const float want_w[] = {-1, -1, -1, -1, -1, 0, 1, 1};
  for (int i = 0; i < 8; ++i) CHECK(into.xyzw[size_t(i) * 4 + 3] == want_w[i]);
  for (float v : into.xyzw) CHECK(std::isfinite(v));
  CHECK_FALSE(decode_depths(bytes.data(), bytes.size() - 1, row, va, a.layout, into));
  CHECK_FALSE(decode_depths(bytes.data(), bytes.size(), Rect{space.x1 - 4, 0, space.x1 + 4, 1}, va, a.layout, into));
  ReprojectStats hs;
  const CostMap safe = reproject(cost, into, ViewRays::of(b, W, H), a.layout, &hs);
  CHECK(safe.cost.size() == size_t(space.area()));
}

TEST_CASE("Carried in blocks of packets, the cost lands within a block of where it belongs", "[reproject]") {
  const Frame a = render_view(look({0, 0, 0}, {0, 0, -1}, kFov));
  const float yaw = 4 * kPi / 180;
  const Camera b = look({0, 0, 0}, {std::sin(yaw), 0.02f, -std::cos(yaw)}, kFov);
  const CostMap cost = x_costs(a);
  // Under the same camera the total is kept (up to rounding a block's cost over its packets).
  ReprojectStats same_st;
  const CostMap same = reproject_blocks(cost, a.r.points, ViewRays::of(a.cam, W, H), a.layout, 2, &same_st);
  CHECK_FALSE(same_st.cut);
  CHECK(std::fabs(double(same.total()) - double(cost.total())) < 0.001 * double(cost.total()));
  // After the turn, each packet reads a position within a block (2 packets) of the truth.
  ReprojectStats st;
  const CostMap moved = reproject_blocks(cost, a.r.points, ViewRays::of(b, W, H), a.layout, 2, &st);
  CHECK_FALSE(st.cut);
  REQUIRE(moved.packets == cost.packets);
  const auto [checked, close] = wall_packets_near(moved, a, b, 1.5);
  INFO(checked << " wall packets, " << close << " within 1.5 packets; " << st.filled << " blocks filled");
  CHECK(checked > moved.packets.area() * 6 / 10);
  CHECK(close >= checked * 95 / 100);
  // block 1 is reproject() itself; a turn of 180 degrees is a cut, the map comes back.
  ReprojectStats cut_st;
  const CostMap back = reproject_blocks(cost, a.r.points, ViewRays::of(look({0, 0, 0}, {0, 0, 1}, kFov), W, H), a.layout, 2, &cut_st);
  CHECK(cut_st.cut);
  CHECK(back.cost == cost.cost);
}
