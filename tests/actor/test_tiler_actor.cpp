// The tiler actor's predictors (actors/tiler_actor.cpp): the SATs and depths of frame f-1 and
// frame f's camera give a tiling from the last frame's cost carried into the new view
// (lb/reproject.h); without depths or a camera, or when the camera did not move, the paper's
// previous-frame map; after a cut, the previous SATs. Synthetic: a wall 20 units in front of a
// camera, with an expensive vertical strip on it; the camera then moves sideways, so the strip
// moves across the image and the previous frame's tiling is wrong by the move.
#include <catch2/catch.hpp>

#include <cmath>
#include <cstring>

#include <caf/all.hpp>

#include "actors/node.h"
#include "lb/reproject.h"
#include "lb/sat.h"
#include "lb/tiler.h"

using namespace tessera;

namespace {

constexpr int32_t W = 256, H = 144;
constexpr PacketLayout kLayout{4, 4};
constexpr float kWall = 20;

Camera at_x(float x) {
  Camera c;
  c.to_world = Mat4::translate({x, 0, 0});
  c.fov_y = 1.0471976f;
  return c;
}

// The cost of each packet seen from `cam`: the wall's cost at the x its centre ray hits.
CostMap wall_costs(const Camera& cam) {
  const ViewRays v = ViewRays::of(cam, W, H);
  const Rect space = packet_space(W, H, kLayout);
  CostMap m{space, std::vector<uint32_t>(size_t(space.area()))};
  for (int32_t py = 0; py < space.y1; ++py)
    for (int32_t px = 0; px < space.x1; ++px) {
      const Vec3 d = v.direction((float(px) + 0.5f) * kLayout.w, (float(py) + 0.5f) * kLayout.h);
      const float x = v.eye.x + kWall * d.x;
      m.cost[size_t(py) * size_t(space.x1) + size_t(px)] = (x > -9 && x < -3) ? 9000 : 1000;
    }
  return m;
}

// Frame f-1 as two nodes report it: the left and the right half of the packet space, each with
// its SAT and (with_depths) its depths.
SatReport report(const Camera& cam, bool with_depths) {
  const CostMap all = wall_costs(cam);
  const Rect space = all.packets;
  SatReport r{1, W, H, kLayout.w, kLayout.h, {}, {}, {}, {}};
  const int32_t mid = space.x1 / 2;
  for (const Rect& half : {Rect{0, 0, mid, space.y1}, Rect{mid, 0, space.x1, space.y1}}) {
    CostMap part{half, {}};
    std::vector<float> depth;
    for (int32_t py = half.y0; py < half.y1; ++py)
      for (int32_t px = half.x0; px < half.x1; ++px) {
        part.cost.push_back(all.at(px, py));
        depth.push_back(kWall);  // the camera looks down -z with a unit basis: depth = distance to the wall
      }
    r.sats.push_back(Sat::from_cost_map_serial(part).serialize());
    r.perf.push_back(1.0);
    std::vector<uint8_t> bytes(depth.size() * 4);
    std::memcpy(bytes.data(), depth.data(), bytes.size());
    r.depths.push_back(with_depths ? bytes : std::vector<uint8_t>{});
  }
  r.camera = pack_camera(cam);
  return r;
}

// The largest task's share of `truth` against the mean (1 = perfectly balanced).
double balance(const std::vector<Rect>& pixel_tasks, const CostMap& truth) {
  SatArray arr(truth.packets);
  arr.add(Sat::from_cost_map_serial(truth));
  arr.finalize();
  double worst = 0, sum = 0;
  for (const Rect& t : pixel_tasks) {
    const double c = arr.cost(pixels_to_packets(t, kLayout));
    worst = std::max(worst, c);
    sum += c;
  }
  return worst / (sum / double(pixel_tasks.size()));
}

struct Fixture {
  caf::actor_system_config cfg;
  std::unique_ptr<caf::actor_system> sys;
  std::unique_ptr<caf::scoped_actor> self;
  tiler_actor tiler;
  Fixture() {
    register_message_types(cfg);
    sys = std::make_unique<caf::actor_system>(cfg);
    self = std::make_unique<caf::scoped_actor>(*sys);
    tiler = spawn_tiler(*sys, std::vector<double>(8, 1.0));
  }
  ~Fixture() { (*self)->send_exit(tiler, caf::exit_reason::user_shutdown); }
  TaskList tasks(std::vector<float> camera) {
    (*self)->send(tiler, sats_atom::value, pending);
    TaskList out;
    (*self)
        ->request(tiler, caf::infinite, tasks_atom::value, TaskRequest{2, W, H, kLayout.w, kLayout.h, std::move(camera)})
        .receive([&](TaskList& tl) { out = std::move(tl); }, [&](caf::error& e) { FAIL(sys->render(e)); });
    return out;
  }
  SatReport pending;
};

}  // namespace

TEST_CASE("The tiler carries the last frame's cost into the new camera, and falls back where it cannot",
          "[tiler][reproject]") {
  Fixture f;
  const Camera a = at_x(0), b = at_x(2.5f);
  const CostMap truth = wall_costs(b);  // what frame 2 really costs

  f.pending = report(a, true);
  const TaskList moved = f.tasks(pack_camera(b));
  CHECK(moved.from_sats);
  CHECK(Predictor(moved.predictor) == Predictor::reprojected);
  CHECK(moved.reproject_ms > 0);
  CHECK(moved.filled > 0);  // the border that came into view
  REQUIRE(moved.tasks.size() == 8);

  // The paper's predictor on the same report: a request without a camera.
  const TaskList plain = f.tasks({});
  CHECK(Predictor(plain.predictor) == Predictor::previous);
  CHECK(plain.reproject_ms == 0);
  // Against the true cost of the new frame, and the best a tiling of whole packets can do (the
  // tiler given the truth itself).
  SatArray known(truth.packets);
  known.add(Sat::from_cost_map_serial(truth));
  known.finalize();
  std::vector<Rect> best;
  for (const Rect& r : tile(&known, truth.packets, std::vector<double>(8, 1.0)))
    best.push_back(packets_to_pixels(r, kLayout, W, H));
  const double b_moved = balance(moved.tasks, truth), b_plain = balance(plain.tasks, truth), b_best = balance(best, truth);
  INFO("balance on the true cost of the new frame: reprojected " << b_moved << ", previous frame " << b_plain
                                                                 << ", tiled from the truth " << b_best);
  CHECK(b_moved <= b_best + 0.03);
  CHECK(b_plain > b_best + 0.5);

  // The same tiles as the library gives for the carried map (the actor adds nothing of its own).
  {
    SatArray prev(truth.packets);
    for (const auto& s : f.pending.sats) prev.add(Sat::deserialize(s));
    prev.finalize();
    PacketPoints pts{truth.packets, std::vector<float>(size_t(truth.packets.area()) * 4, -1.0f)};
    const ViewRays va = ViewRays::of(a, W, H);
    for (size_t i = 0; i < 2; ++i) {
      const Sat s = Sat::deserialize(f.pending.sats[i]);
      REQUIRE(decode_depths(f.pending.depths[i].data(), f.pending.depths[i].size(), s.packets(), va, kLayout, pts));
    }
    SatArray one(truth.packets);
    one.add(Sat::from_cost_map(reproject(prev.cost_map(), pts, ViewRays::of(b, W, H), kLayout)));
    one.finalize();
    const std::vector<Rect> want = tile(&one, truth.packets, std::vector<double>(8, 1.0));
    for (size_t i = 0; i < want.size(); ++i) CHECK(moved.tasks[i] == packets_to_pixels(want[i], kLayout, W, H));
  }

  // The camera did not move: the previous SATs as they are (nothing to carry).
  const TaskList still = f.tasks(pack_camera(a));
  CHECK(Predictor(still.predictor) == Predictor::previous);
  for (size_t i = 0; i < still.tasks.size(); ++i) CHECK(still.tasks[i] == plain.tasks[i]);

  // A report without depths (the rasterizer, or a worker that gave none): previous frame.
  f.pending = report(a, false);
  CHECK(Predictor(f.tasks(pack_camera(b)).predictor) == Predictor::previous);

  // Depths of the wrong size, or a camera that is not 17 finite floats: ignored, no harm.
  f.pending = report(a, true);
  f.pending.depths[0].pop_back();
  const TaskList half = f.tasks(pack_camera(b));  // the right half's depths still count
  CHECK(Predictor(half.predictor) != Predictor::area);
  f.pending = report(a, true);
  f.pending.camera[3] = std::nanf("");
  CHECK(Predictor(f.tasks(pack_camera(b)).predictor) == Predictor::previous);
  f.pending = report(a, true);
  std::vector<float> bad = pack_camera(b);
  bad.pop_back();
  CHECK(Predictor(f.tasks(bad).predictor) == Predictor::previous);

  // A cut: the camera turned around. The previous SATs are used, never a degenerate tiling.
  Camera back = a;
  back.to_world = Mat4::rotate({0, 1, 0}, kPi);
  f.pending = report(a, true);
  const TaskList cut = f.tasks(pack_camera(back));
  CHECK(Predictor(cut.predictor) == Predictor::cut);
  for (size_t i = 0; i < cut.tasks.size(); ++i) CHECK(cut.tasks[i] == plain.tasks[i]);

  // Another size: an even split by area, whatever the report had.
  (*f.self)->send(f.tiler, sats_atom::value, report(a, true));
  TaskList other;
  (*f.self)
      ->request(f.tiler, caf::infinite, tasks_atom::value, TaskRequest{3, 128, 72, kLayout.w, kLayout.h, pack_camera(b)})
      .receive([&](TaskList& tl) { other = std::move(tl); }, [&](caf::error&) { FAIL("no task list"); });
  CHECK(Predictor(other.predictor) == Predictor::area);
  CHECK_FALSE(other.from_sats);
}

// A still's partial rounds (adaptive refinement): their SATs tile the next partial round, and
// the whole frame's SATs stay for the frames after the still.
TEST_CASE("The tiler keeps a partial round's SATs apart from the last whole frame's", "[tiler][adaptive]") {
  Fixture f;
  const Camera a = at_x(0);
  auto ask = [&](bool partial) {
    TaskRequest req{2, W, H, kLayout.w, kLayout.h, {}};
    req.partial = partial;
    TaskList out;
    (*f.self)
        ->request(f.tiler, caf::infinite, tasks_atom::value, req)
        .receive([&](TaskList& tl) { out = std::move(tl); }, [&](caf::error& e) { FAIL(f.sys->render(e)); });
    return out;
  };
  (*f.self)->send(f.tiler, sats_atom::value, report(a, false));
  const TaskList whole = ask(false);
  CHECK(ask(true).tasks == whole.tasks);  // no partial round yet: the whole frame's map
  // A partial round that rendered only the left quarter of the image (the rest cost 0).
  const Rect space = packet_space(W, H, kLayout);
  CostMap part{space, std::vector<uint32_t>(size_t(space.area()), 0)};
  for (int32_t py = 0; py < space.y1; ++py)
    for (int32_t px = 0; px < space.x1 / 4; ++px) part.cost[size_t(py) * size_t(space.x1) + size_t(px)] = 1000;
  SatReport partial{2, W, H, kLayout.w, kLayout.h, {Sat::from_cost_map_serial(part).serialize()}, {1.0}, {{}}, {}, true};
  (*f.self)->send(f.tiler, sats_atom::value, partial);
  const TaskList next_round = ask(true);
  REQUIRE(next_round.tasks.size() == 8);
  // Balanced on what the next partial round costs, where the whole frame's tiling is not.
  const double b_partial = balance(next_round.tasks, part), b_whole = balance(whole.tasks, part);
  INFO("balance on the partial round's cost: tiled from it " << b_partial << ", from the whole frame " << b_whole);
  CHECK(b_partial < 1.1);
  CHECK(b_whole > 2);
  CHECK(ask(false).tasks == whole.tasks);  // a frame after the still: the whole frame's map
  // A partial report of another size is dropped; a whole frame's report ends the partial map.
  SatReport other = partial;
  other.width = 128;
  (*f.self)->send(f.tiler, sats_atom::value, other);
  CHECK(ask(true).tasks == whole.tasks);
  (*f.self)->send(f.tiler, sats_atom::value, partial);
  (*f.self)->send(f.tiler, sats_atom::value, report(a, false));
  CHECK(ask(true).tasks == whole.tasks);
}
