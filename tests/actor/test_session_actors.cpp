// Deterministic tests of the session pipeline (session -> frame -> tiler -> root subtree ->
// renderer -> display -> encoder) with CAF's test coordinator: every message is delivered by the test, one at a
// time, on one thread. The renderer and encoder are real (not detached) and render a tiny
// scene, so the pixels, SATs and encodings are the production code's.
#define CAF_SUITE session_actors
#include <caf/test/dsl.hpp>
#include <caf/test/unit_test_impl.hpp>

#include <mutex>

#include "actors/checks.h"
#include "actors/node.h"
#include "codecs/h264.h"
#include "codecs/jpeg.h"
#include "protocol/protocol.h"
#include "renderer/accumulation.h"
#include "renderer/raytracer.h"
#include "renderer/sampling.h"
#include "tests/actor/actor_helpers.h"

using namespace tessera;
using namespace tessera::protocol;
using namespace tessera::test;

namespace {

struct fixture : test_coordinator_fixture<TestConfig> {
  std::shared_ptr<RecordingSink> sink = std::make_shared<RecordingSink>();
  std::shared_ptr<NodeSettings> settings = std::make_shared<NodeSettings>();
  std::shared_ptr<MemoryBudget> budget = std::make_shared<MemoryBudget>(1u << 20);
  size_t baseline = 0;
  session_actor session;
  caf::actor renderer, tiler, encoder, display, frame, subtree;

  explicit fixture(DisplayKind display_kind = DisplayKind::jpeg) {
    settings->detached = false;  // everything on the test coordinator
    settings->packet_layout = {4, 4};
    settings->log = [](const Event&) {};
    settings->handshake_timeout_ms = 0;  // run() advances the clock: the timeout has its own tests
    settings->budget = budget;
    // Every still refined uniformly: the tests below compare its frames with plain averages
    // byte for byte; the adaptive rounds (renderer/adaptive.h) have tests of their own.
    settings->adaptive_round = 0;
    run();
    baseline = sys.registry().running();
    session = spawn_session(sys, sink, settings, 1);
    run();
    auto rh = self->request(session, caf::infinite, children_atom::value);
    run();
    rh.receive([&](std::vector<caf::actor>& c) {
      CAF_REQUIRE_EQUAL(c.size(), 6u);
      renderer = c[0], tiler = c[1], encoder = c[2], display = c[3], frame = c[4], subtree = c[5];
    },
               [&](caf::error& e) { CAF_FAIL(sys.render(e)); });
    Handshake hs;
    hs.width = 16;
    hs.height = 16;
    hs.display = display_kind;
    client({hs});
    client(tiny_scene());
    run();
  }
  ~fixture() override {
    self->send_exit(session, caf::exit_reason::user_shutdown);
    run();
  }
  void client(const std::vector<ClientRecord>& recs) { self->send(session, client_atom::value, encode(recs)); }
  // A frame starts: the frame actor has the node list of the handshake (the tree did not
  // change) and asks the tiler for the tasks.
  void expect_frame_start() {
    expect((render_atom, FrameStart), from(session).to(frame));
    expect((tasks_atom, TaskRequest), from(frame).to(tiler));
    expect((TaskList), from(tiler).to(frame));
  }
  // The frame's batch goes through the root subtree to this node's renderer; the root gets the
  // session's scene with the first batch only (the scene object stays the same).
  void expect_render(bool first) {
    if (first) expect((scene_atom, SceneSnapshot), from(frame).to(subtree));
    expect((render_atom, RenderBatch), from(frame).to(subtree));
    expect((render_atom, SceneSnapshot, RenderTask), from(subtree).to(renderer));
  }
  // Delivers the next client message to the session (and nothing else).
  void deliver_client() { expect((client_atom, std::vector<uint8_t>), from(self).to(session)); }
  SessionStatus status() {
    auto rh = self->request(session, caf::infinite, status_atom::value);
    expect((status_atom), from(self).to(session));
    SessionStatus s;
    rh.receive([&](SessionStatus& x) { s = x; }, [&](caf::error& e) { CAF_FAIL(sys.render(e)); });
    return s;
  }
  // The last frame sent (a copy: CAF's check macros keep references to their arguments).
  Frame last_frame() {
    auto frames = sink->all<Frame>();
    CAF_REQUIRE(!frames.empty());
    return frames.back();
  }
  std::vector<uint32_t> frames_sent() {
    std::vector<uint32_t> out;
    for (auto& f : sink->all<Frame>()) out.push_back(f.frame);
    return out;
  }
};

// A buffer of n floats (0.5), id `id`: 4n bytes against the client's byte limits.
SetBuffer floats(Id id, size_t n) {
  SetBuffer b;
  b.id = id;
  b.buffer.type = Buffer::Type::f32;
  b.buffer.components = 1;
  b.buffer.f.assign(n, 0.5f);
  return b;
}

}  // namespace

CAF_TEST_FIXTURE_SCOPE(session_tests, fixture)

CAF_TEST(scene updates are applied at once between frames and cached while a frame renders) {
  CAF_CHECK_EQUAL(sink->all<HandshakeReply>().size(), 1u);
  auto idle = status();
  CAF_CHECK(idle.handshake_done);
  CAF_CHECK(!idle.in_flight);
  CAF_CHECK_EQUAL(idle.cached_updates, 0u);
  CAF_CHECK_EQUAL(idle.triangles, 2u);  // applied at once: no frame in flight
  client({SetCamera{camera_at(3)}, RenderRequest{1}});
  deliver_client();
  auto rendering = status();
  CAF_CHECK(rendering.in_flight);
  // While the frame renders, a camera move and a light change wait in the cache.
  SetLight brighter;
  brighter.id = 4;
  brighter.light.intensity = 2;
  client({SetCamera{camera_at(4)}, brighter});
  deliver_client();
  auto cached = status();
  CAF_CHECK(cached.in_flight);
  CAF_CHECK_EQUAL(cached.cached_updates, 2u);
  CAF_CHECK_EQUAL(cached.scene_version, rendering.scene_version);  // the rendered scene is untouched
  run();
  auto after = status();
  CAF_CHECK(!after.in_flight);
  CAF_CHECK_EQUAL(after.cached_updates, 0u);
  CAF_CHECK_GREATER(after.scene_version, rendering.scene_version);
  CAF_CHECK_EQUAL(frames_sent(), std::vector<uint32_t>{1});
  CAF_CHECK_EQUAL(sink->all<ErrorReply>().size(), 0u);
}

CAF_TEST(updates cached during a frame count against the byte limit of the client as if applied) {
  settings->limits.max_client_bytes = 72 + 200;  // tiny_scene holds 72 bytes of buffers
  client({SetCamera{camera_at(3)}, RenderRequest{1}});
  deliver_client();
  // 160 bytes fit; 160 more would not, so that buffer is refused now, not after the frame.
  client({floats(10, 40), floats(11, 40), SetCamera{camera_at(4)}});
  deliver_client();
  auto waiting = status();
  CAF_CHECK(waiting.in_flight);
  CAF_CHECK_EQUAL(waiting.cached_updates, 2u);
  auto errors = sink->all<ErrorReply>();
  CAF_REQUIRE_EQUAL(errors.size(), 1u);
  CAF_CHECK(errors[0].code == ErrorCode::limit_exceeded);
  CAF_CHECK_EQUAL(errors[0].record, 1u);
  CAF_CHECK(!errors[0].fatal);
  CAF_CHECK_NOT_EQUAL(errors[0].message.find("buffer 11"), std::string::npos);
  run();  // the frame ends; what was accepted is applied
  CAF_CHECK_EQUAL(frames_sent(), std::vector<uint32_t>{1});
  // Next frame: replacing a waiting buffer counts its old size out, and 40 more bytes fill
  // the limit exactly.
  client({RenderRequest{2}});
  deliver_client();
  client({floats(10, 40), floats(11, 10)});
  deliver_client();
  CAF_CHECK_EQUAL(status().cached_updates, 2u);
  CAF_CHECK_EQUAL(sink->all<ErrorReply>().size(), 1u);
  run();
  CAF_CHECK_EQUAL(frames_sent(), (std::vector<uint32_t>{1, 2}));
  // Now held: 72 + 160 + 40 bytes, the limit. Between frames the same check applies at once.
  client({floats(12, 1)});
  run();
  CAF_CHECK_EQUAL(sink->all<ErrorReply>().size(), 2u);
}

CAF_TEST(render requests during a frame are remembered once and never queued twice) {
  client({SetCamera{camera_at(3)}, RenderRequest{1}});
  deliver_client();
  client({RenderRequest{2}});
  deliver_client();
  auto one = status();
  CAF_CHECK(one.render_pending);
  CAF_CHECK_EQUAL(one.pending_frame, 2u);
  CAF_CHECK_EQUAL(one.dropped, 0u);
  client({RenderRequest{3}});
  deliver_client();
  auto two = status();
  CAF_CHECK(two.render_pending);
  CAF_CHECK_EQUAL(two.pending_frame, 3u);  // the latest request wins
  CAF_CHECK_EQUAL(two.dropped, 1u);        // request 2 merged into 3
  run();
  CAF_CHECK_EQUAL(frames_sent(), (std::vector<uint32_t>{1, 3}));
  auto done = status();
  CAF_CHECK_EQUAL(done.frames_started, 2u);
  CAF_CHECK(!done.render_pending);
  // Idle again: the next request starts a frame at once.
  client({RenderRequest{4}});
  run();
  CAF_CHECK_EQUAL(frames_sent(), (std::vector<uint32_t>{1, 3, 4}));
}

CAF_TEST(the encoder encodes frame f while the renderer renders frame f plus 1) {
  client({SetCamera{camera_at(3)}, RenderRequest{1}, RenderRequest{2}});
  deliver_client();
  expect_frame_start();
  expect_render(true);
  expect((TileResult), from(renderer).to(subtree));
  expect((BatchReply), from(subtree).to(frame));
  // Frame 1 is rendered: its SATs go to the tiler, its pixels to the display channel, and the
  // session, told so, starts frame 2 at once.
  expect((sats_atom, SatReport), from(frame).to(tiler));
  expect((display_atom, FrameTiles), from(frame).to(display));
  expect((uint32_t), from(frame).to(session));
  // Now the encoder holds frame 1 and the renderer frame 2, at the same time: with detached
  // actors these run in parallel.
  expect((encode_atom, EncodeJob), from(display).to(encoder));
  expect_frame_start();
  expect_render(false);
  expect((EncodedFrame), from(encoder).to(display));
  CAF_CHECK_EQUAL(frames_sent(), std::vector<uint32_t>{1});
  run();
  CAF_CHECK_EQUAL(frames_sent(), (std::vector<uint32_t>{1, 2}));
  // Frame 2 was tiled from frame 1's SATs and carries every measurement.
  auto frames = sink->all<Frame>();
  CAF_CHECK_GREATER(frames[1].timings.rendering_ms, 0.f);
  CAF_CHECK_GREATER(frames[1].timings.encode_ms, 0.f);
  CAF_CHECK_GREATER_OR_EQUAL(frames[1].timings.pipeline_ms, frames[1].timings.encode_ms);
  CAF_CHECK_EQUAL(frames[1].width, 16);
  CAF_CHECK(!frames[1].payload.empty());
}

CAF_TEST(frames rendered faster than they encode wait one at a time and the newest wins) {
  // The encoder is held on frame 1 while frames 2, 3 and 4 render: the display keeps one of
  // them waiting (a newer one replaces it), so a client that asks faster than its frames
  // encode costs the node two frames, not a queue.
  auto rendered_to_display = [&] {
    expect_frame_start();
    expect_render(false);
    expect((TileResult), from(renderer).to(subtree));
    expect((BatchReply), from(subtree).to(frame));
    expect((sats_atom, SatReport), from(frame).to(tiler));
    expect((display_atom, FrameTiles), from(frame).to(display));
    expect((uint32_t), from(frame).to(session));
  };
  client({SetCamera{camera_at(3)}, RenderRequest{1}, RenderRequest{2}});
  deliver_client();
  expect_frame_start();
  expect_render(true);
  expect((TileResult), from(renderer).to(subtree));
  expect((BatchReply), from(subtree).to(frame));
  expect((sats_atom, SatReport), from(frame).to(tiler));
  expect((display_atom, FrameTiles), from(frame).to(display));
  expect((uint32_t), from(frame).to(session));
  // Frame 1's job is in the encoder's mailbox, left there: the encoder is busy.
  rendered_to_display();  // frame 2 waits
  for (uint32_t f : {3u, 4u}) {
    client({RenderRequest{f}});
    deliver_client();
    rendered_to_display();  // replaces the waiting frame
  }
  // The encoder's mailbox holds frame 1's job only: nothing else was handed to it.
  CAF_CHECK_EQUAL(frames_sent(), std::vector<uint32_t>{});
  run();
  CAF_CHECK_EQUAL(frames_sent(), (std::vector<uint32_t>{1, 4}));
  CAF_CHECK_EQUAL(sink->all<ErrorReply>().size(), 0u);
  // Idle again: the next frame goes straight to the encoder.
  client({RenderRequest{5}});
  run();
  CAF_CHECK_EQUAL(frames_sent(), (std::vector<uint32_t>{1, 4, 5}));
}

// The still the session refines, rendered and averaged here without actors: `samples` samples
// of tiny_scene() seen from camera_at(z) at 16x16, seeded by frame `seed`, JPEG at quality 85.
std::vector<uint8_t> refined_still(float z, uint32_t seed, uint32_t samples) {
  Scene scene;
  std::vector<ClientRecord> recs = tiny_scene();
  recs.push_back(SetCamera{camera_at(z)});
  CAF_REQUIRE_EQUAL(apply_records(scene, encode(recs), Limits{}), "");
  scene.set_resolution(16, 16);
  RayTracer rt({4, 4});
  std::vector<std::string> warnings;
  rt.sync(scene, warnings);
  Accumulation acc;
  acc.reset(16, 16, scene.environment().linear);
  for (uint32_t k = 0; k < samples; ++k) {
    RenderSettings s;
    s.ao_samples = 0;
    s.max_depth = 4;
    s.frame = seed;
    s.sample = k;
    s.radiance = true;
    TaskResult r;
    rt.render(Rect{0, 0, 16, 16}, s, r);
    acc.add(r.radiance, 16, 16, 0, 0);
    acc.end_sample();
  }
  Image avg = acc.average();
  JpegEncoder jpeg;
  std::vector<uint8_t> out;
  std::string err;
  CAF_REQUIRE(jpeg.encode(avg.rgba.data(), 16, 16, 85, out, err, 0));
  return out;
}

CAF_TEST(after a requested frame the still refines to its target and the session goes idle) {
  settings->refine_samples = 4;  // the node's default: this client sends no refine record
  client({SetCamera{camera_at(3)}, RenderRequest{1}});
  run();
  auto frames = sink->all<Frame>();
  CAF_REQUIRE_GREATER_OR_EQUAL(frames.size(), 2u);
  for (auto& f : frames) CAF_CHECK_EQUAL(f.frame, 1u);  // refinements carry the requested frame's number
  CAF_CHECK(!frames.front().refined);
  CAF_CHECK_EQUAL(frames.front().samples, 1u);
  CAF_CHECK(frames.back().refined);
  CAF_CHECK_EQUAL(frames.back().samples, 4u);
  for (size_t i = 1; i < frames.size(); ++i) CAF_CHECK_GREATER(frames[i].samples, frames[i - 1].samples);
  // The average of the four samples, exactly as the renderer and an Accumulation give it.
  CAF_CHECK(frames.back().payload == refined_still(3, 1, 4));
  CAF_CHECK(frames.front().payload == refined_still(3, 1, 1));  // sample 0 is the plain frame
  // Converged: nothing more is rendered.
  CAF_CHECK_EQUAL(status().frames_started, 4u);
  run();
  CAF_CHECK_EQUAL(status().frames_started, 4u);
  CAF_CHECK_EQUAL(sink->all<Frame>().size(), frames.size());
  CAF_CHECK_EQUAL(sink->all<ErrorReply>().size(), 0u);
}

CAF_TEST(any client message ends the refinement and a render request starts a new still) {
  settings->refine_samples = 6;
  client({SetCamera{camera_at(3)}, RenderRequest{1}});
  // Queued behind the first: it arrives while frame 1 renders, so frame 1 is never refined.
  client({SetCamera{camera_at(4)}, RenderRequest{2}});
  run();
  auto frames = sink->all<Frame>();
  CAF_REQUIRE_GREATER_OR_EQUAL(frames.size(), 2u);
  CAF_CHECK_EQUAL(frames.front().frame, 1u);
  CAF_CHECK_EQUAL(frames.front().samples, 1u);
  for (auto& f : frames)
    if (f.frame == 1) CAF_CHECK(!f.refined);
  CAF_CHECK_EQUAL(frames.back().frame, 2u);
  CAF_CHECK_EQUAL(frames.back().samples, 6u);
  CAF_CHECK(frames.back().payload == refined_still(4, 2, 6));  // seeded by its own first frame (seq 2)
  CAF_CHECK_EQUAL(status().frames_started, 1u + 6u);
  // A message without a render request (a light change) stops a still midway; the next
  // request starts over at sample 0.
  const size_t before = sink->all<Frame>().size();
  client({SetCamera{camera_at(3)}, RenderRequest{3}});
  deliver_client();
  SetLight dim;
  dim.id = 4;
  dim.light.intensity = 0.5f;
  client({dim});
  run();
  auto later = sink->all<Frame>();
  CAF_REQUIRE_GREATER(later.size(), before);
  CAF_CHECK_EQUAL(later.back().frame, 3u);
  CAF_CHECK_EQUAL(later.back().samples, 1u);  // the light change arrived while sample 0 rendered
  CAF_CHECK_EQUAL(status().frames_started, 1u + 6u + 1u);
}

CAF_TEST(every kind of client record ends a still that is refining) {
  settings->refine_samples = 64;
  SetLight light;
  light.id = 4;
  light.light.type = Light::Type::directional;
  light.light.direction = {0, 0, -1};
  SetEnvironment env;
  env.environment.ambient = {0.1f, 0.1f, 0.1f};
  SetMaterial mat;
  mat.id = 20;
  SetMesh mesh;
  mesh.id = 3;
  mesh.mesh.positions = 1;
  mesh.mesh.indices = 2;
  Remove gone;
  gone.what = RecordType::material;
  gone.id = 20;
  const std::vector<std::pair<std::string, ClientRecord>> changes = {
      {"settings", Settings{0, 3}}, {"resolution", Resolution{16, 16}}, {"camera", SetCamera{camera_at(4)}},
      {"environment", env},         {"light", light},                   {"material", mat},
      {"mesh", mesh},               {"remove", gone},                   {"refine", Refine{64}},
      {"buffer", floats(40, 4)},    {"budget", Budget{33}}};
  uint32_t frame = 0;
  for (auto& [name, rec] : changes) {
    CAF_MESSAGE("change: " << name);
    const uint32_t before = status().frames_started;
    client({SetCamera{camera_at(3)}, RenderRequest{++frame}});
    deliver_client();  // sample 0 renders
    for (int i = 0; i < 40; ++i) sched.run_once();  // a few samples further
    const uint32_t started = status().frames_started;
    CAF_CHECK_GREATER(started, before + 2);  // it was refining
    client({rec});
    run();
    const uint32_t after = status().frames_started;
    CAF_CHECK_LESS_OR_EQUAL(after, started + 1);  // at most the sample in flight finishes
    const Frame last = last_frame();
    CAF_CHECK_LESS(last.samples, 64u);
    run();
    CAF_CHECK_EQUAL(status().frames_started, after);  // and then nothing
  }
  CAF_CHECK_EQUAL(sink->all<ErrorReply>().size(), 0u);
}

CAF_TEST(a still whose average would not fit the memory budget is not refined and the client is told) {
  settings->refine_samples = 8;
  // A 512x512 still holds 13 MiB (AdaptiveStill::bytes), over the whole budget (1 MiB): refused.
  client({Resolution{512, 512}, SetCamera{camera_at(3)}, RenderRequest{1}});
  run();
  auto frames = sink->all<Frame>();
  CAF_REQUIRE_EQUAL(frames.size(), 1u);
  CAF_CHECK_EQUAL(frames[0].samples, 1u);
  CAF_CHECK_EQUAL(status().frames_started, 1u);
  auto errors = sink->all<ErrorReply>();
  CAF_REQUIRE_EQUAL(errors.size(), 1u);
  CAF_CHECK_EQUAL(errors[0].code, ErrorCode::limit_exceeded);
  CAF_CHECK(!errors[0].fatal);
  CAF_CHECK_NOT_EQUAL(errors[0].message.find("memory budget"), std::string::npos);
  // A small one fits, and what it holds is counted until the next still.
  const uint64_t before = budget->used();
  client({Resolution{64, 64}, RenderRequest{2}});
  run();
  const Frame refined = last_frame();
  CAF_CHECK_EQUAL(refined.samples, 8u);
  CAF_CHECK_EQUAL(sink->all<ErrorReply>().size(), 1u);
  CAF_CHECK_EQUAL(budget->used(), before + AdaptiveStill::bytes(64, 64));
}

// A floor and a wall meeting at a corner under a sky (docs/renderer.md, "Denoising a still's
// first samples"): ambient occlusion that finds occluders, so a still with AO is noisy.
std::vector<ClientRecord> corner_scene() {
  SetBuffer pos;
  pos.id = 11;
  pos.buffer.type = Buffer::Type::f32;
  pos.buffer.components = 3;
  pos.buffer.f = {-2, -1, -2, 2, -1, -2, 2, -1, 2, -2, -1, 2,   // the floor, y = -1
                  -2, -1, -1, 2, -1, -1, 2, 2, -1, -2, 2, -1};  // the wall, z = -1
  SetBuffer idx;
  idx.id = 12;
  idx.buffer.type = Buffer::Type::u32;
  idx.buffer.components = 1;
  idx.buffer.u = {0, 1, 2, 0, 2, 3, 4, 5, 6, 4, 6, 7};
  SetMaterial white;
  white.id = 14;
  white.material.model = Material::Model::diffuse;
  white.material.diffuse_color = {0.5f, 0.5f, 0.5f};
  SetMesh mesh;
  mesh.id = 13;
  mesh.mesh.positions = 11;
  mesh.mesh.indices = 12;
  mesh.mesh.material = 14;
  SetEnvironment env;
  env.environment.ambient = {0.6f, 0.6f, 0.6f};
  env.environment.background = {0.2f, 0.3f, 0.4f};
  return {pos, idx, white, mesh, env, SetCamera{camera_at(3)}};
}

// What the client sends beside the scene: one AO ray per hit, 32x32.
std::vector<ClientRecord> corner_session() {
  std::vector<ClientRecord> recs = corner_scene();
  recs.push_back(protocol::Settings{1, 4});
  recs.push_back(Resolution{32, 32});
  return recs;
}

// The plain averages of a still's first 1, 2, ..., `samples` samples of `recs`, seeded by frame
// `seed`, as the session's renderer and frame actor make them: element n - 1 averages n
// samples. The first sample traces `first_ao` AO rays per hit (the session's: one), the later
// ones `ao` (the node's still-ao-samples). One pass (the tests also run under ASan).
std::vector<Image> plain_averages(const std::vector<ClientRecord>& recs, uint32_t seed, uint32_t samples,
                                  int32_t first_ao = 1, int32_t ao = sampling::kStillAoSamples) {
  Scene scene;
  CAF_REQUIRE_EQUAL(apply_records(scene, encode(recs), Limits{}), "");
  scene.set_resolution(32, 32);
  RayTracer rt({4, 4});
  std::vector<std::string> warnings;
  rt.sync(scene, warnings);
  const Rect full{0, 0, scene.width(), scene.height()};
  Accumulation acc;
  acc.reset(full.width(), full.height(), scene.environment().linear);
  std::vector<Image> out;
  for (uint32_t k = 0; k < samples; ++k) {
    RenderSettings s;
    s.ao_samples = k == 0 ? first_ao : ao;
    s.frame = seed;
    s.sample = k;
    s.radiance = true;
    TaskResult r;
    rt.render(full, s, r);
    acc.add(r.radiance, full.width(), full.height(), 0, 0);
    acc.end_sample();
    out.push_back(acc.average());
  }
  return out;
}

// An image through the JPEG display's encoding (quality 85) and back.
Image through_jpeg(const Image& img) {
  JpegEncoder jpeg;
  std::vector<uint8_t> bytes;
  std::string err;
  CAF_REQUIRE(jpeg.encode(img.rgba.data(), img.width, img.height, 85, bytes, err, 0));
  Image out;
  CAF_REQUIRE(jpeg_decode(bytes.data(), bytes.size(), out, err));
  return out;
}

Image decoded(const Frame& f) {
  Image out;
  std::string err;
  CAF_REQUIRE(jpeg_decode(f.payload.data(), f.payload.size(), out, err));
  return out;
}

CAF_TEST(a still with AO under a sky is denoised while noisy and shows fewer and better frames) {
  settings->refine_samples = 16;
  settings->denoise_below_db = 99;  // denoised to its end
  // One AO ray per sample, the noisiest still: with the node's four the plain average of this
  // tiny image passes 36 dB (below) after five samples.
  settings->still_ao_samples = 1;
  std::vector<ClientRecord> recs = tiny_scene();  // the fixture's, and the corner
  for (auto& r : corner_scene()) recs.push_back(r);
  client(corner_session());
  client({RenderRequest{1}});
  run();
  std::vector<uint32_t> samples;
  auto frames = sink->all<Frame>();
  for (auto& f : frames) samples.push_back(f.samples);
  // Every sample is rendered; shown are the first four, then a quarter more each time, and the last.
  CAF_CHECK_EQUAL(samples, (std::vector<uint32_t>{1, 2, 3, 4, 5, 6, 7, 8, 10, 12, 15, 16}));
  CAF_CHECK_EQUAL(status().frames_started, 16u);
  CAF_CHECK_EQUAL(sink->all<ErrorReply>().size(), 0u);
  // The requested frame is the plain one. Each denoised frame is closer than the plain average
  // of as many samples to what those samples converge to with AO alone converged (64 rays
  // each, at the same sub-pixel positions: the anti-aliasing is not the denoiser's to do), all
  // through the same JPEG encoding (whose error at 32x32 would otherwise outweigh the noise).
  const std::vector<Image> plain = plain_averages(recs, 1, 16, 1, 1), converged = plain_averages(recs, 1, 16, 64, 64);
  CAF_CHECK(decoded(frames[0]).rgba == through_jpeg(plain[0]).rgba);
  for (size_t i = 1; i < frames.size(); ++i) {
    const uint32_t n = frames[i].samples;
    const Image reference = through_jpeg(converged[n - 1]);
    const double denoised = compare(decoded(frames[i]), reference).psnr;
    const double plain_db = compare(through_jpeg(plain[n - 1]), reference).psnr;
    CAF_MESSAGE(n << " samples: denoised " << denoised << " dB, plain " << plain_db << " dB");
    // Past about 36 dB on this tiny image the filter's blur costs as much as it removes.
    if (n <= 8) CAF_CHECK_GREATER(denoised, plain_db + 1.0);
  }
}

CAF_TEST(a still is denoised until the estimate of its plain average reaches the threshold and plain after) {
  settings->refine_samples = 24;  // the default threshold: kDenoiseBelowDb
  // Held by the log itself: the fixture's teardown still logs (the session's end) after this
  // body's locals are gone.
  auto mu = std::make_shared<std::mutex>();
  auto logged = std::make_shared<std::vector<Event>>();
  settings->log = [mu, logged](const Event& e) {
    std::lock_guard<std::mutex> lock(*mu);
    if (e.kind == Ev::frame) logged->push_back(e);
  };
  std::vector<ClientRecord> recs = tiny_scene();  // the fixture's, and the corner
  for (auto& r : corner_scene()) recs.push_back(r);
  client(corner_session());
  client({RenderRequest{1}});
  run();
  auto frames = sink->all<Frame>();
  std::vector<Event> shown;
  {
    std::lock_guard<std::mutex> lock(*mu);
    shown = *logged;
  }
  CAF_REQUIRE_EQUAL(frames.size(), shown.size());
  const std::vector<Image> plain = plain_averages(recs, 1, 24);
  CAF_CHECK_EQUAL(frames.back().samples, 24u);
  CAF_CHECK_EQUAL(status().frames_started, 24u);
  bool plain_since = false;
  size_t denoised = 0;
  for (size_t i = 1; i < frames.size(); ++i) {
    const Json* est = shown[i].field("estimated_db");
    const Json* den = shown[i].field("denoised");
    const bool is_denoised = den && den->as_bool();
    if (is_denoised) {
      ++denoised;
      CAF_CHECK(!plain_since);  // no going back
      CAF_REQUIRE(est);
      CAF_CHECK_LESS(est->as_double(), kDenoiseBelowDb);
    } else {
      if (!plain_since && est) CAF_CHECK_GREATER_OR_EQUAL(est->as_double(), kDenoiseBelowDb);  // the frame that passed
      plain_since = true;
      CAF_CHECK(decoded(frames[i]).rgba == through_jpeg(plain[frames[i].samples - 1]).rgba);
    }
  }
  CAF_CHECK_GREATER(denoised, 2u);
  CAF_CHECK(plain_since);
}

CAF_TEST(a render request while a sample of a still is denoised stops the denoising and that picture is not shown) {
  settings->refine_samples = 16;
  settings->denoise_below_db = 99;  // denoised to its end
  auto mu = std::make_shared<std::mutex>();
  auto abandoned = std::make_shared<std::vector<Event>>();
  settings->log = [mu, abandoned](const Event& e) {
    std::lock_guard<std::mutex> lock(*mu);
    if (e.kind == Ev::abandoned) abandoned->push_back(e);
  };
  client(corner_session());
  client({RenderRequest{1}});
  // Step until the denoising worker of one of the still's samples has its request waiting
  // (the sample rendered and averaged, its picture not yet made).
  auto denoise_waiting = [&] {
    for (caf::resumable* job : sched.jobs) {
      auto* a = dynamic_cast<caf::scheduled_actor*>(job);
      const caf::mailbox_element* e = a ? a->peek_at_next_mailbox_element() : nullptr;
      if (e && e->content().match_elements<caf::atom_value>() &&
          e->content().get_as<caf::atom_value>(0) == caf::atom("denoise"))
        return true;
    }
    return false;
  };
  bool waiting = false;
  for (int i = 0; i < 100000 && !(waiting = denoise_waiting()); ++i)
    if (!sched.try_run_once()) break;
  CAF_REQUIRE(waiting);
  const auto before = sink->all<Frame>();
  CAF_REQUIRE(!before.empty());
  const uint32_t shown_samples = before.back().samples;
  // The request reaches the session, which abandons the still's sample in flight, before the
  // worker runs: the worker finds its stop raised.
  client({RenderRequest{2}});
  deliver_client();
  expect((cancel_atom, uint32_t), from(session).to(frame));
  run();
  {
    std::lock_guard<std::mutex> lock(*mu);
    CAF_REQUIRE_EQUAL(abandoned->size(), 1u);
    const Json* stage = abandoned->front().field("stage");
    CAF_REQUIRE(stage);
    CAF_CHECK_EQUAL(stage->as_string(), "denoising");
  }
  // After the pictures shown before the request, the next frame is frame 2's first: the
  // denoised sample of frame 1 never went out.
  const auto after = sink->all<Frame>();
  CAF_REQUIRE_GREATER(after.size(), before.size());
  CAF_CHECK_EQUAL(after[before.size()].frame, 2u);
  CAF_CHECK_EQUAL(after[before.size()].samples, 1u);
  for (size_t i = before.size(); i < after.size(); ++i) CAF_CHECK_EQUAL(after[i].frame, 2u);
  CAF_CHECK_LESS(shown_samples, 16u);
  CAF_CHECK_EQUAL(sink->all<ErrorReply>().size(), 0u);
}

CAF_TEST(a still is averaged plainly once its estimate passes the threshold and when denoising is off) {
  settings->refine_samples = 6;
  std::vector<ClientRecord> recs = tiny_scene();  // the fixture's, and the corner
  for (auto& r : corner_scene()) recs.push_back(r);
  for (double below : {1.0, 0.0}) {  // 1 dB: passed at the first estimate; 0: never denoised
    settings->denoise_below_db = below;
    {
      std::lock_guard<std::mutex> lock(sink->mu);
      sink->records.clear();
    }
    client(corner_session());
    client({RenderRequest{uint32_t(below + 1)}});
    run();
    std::vector<uint32_t> samples;
    auto frames = sink->all<Frame>();
    for (auto& f : frames) samples.push_back(f.samples);
    CAF_CHECK_EQUAL(samples, (std::vector<uint32_t>{1, 2, 3, 4, 5, 6}));
    // Every frame the plain average, as without a denoiser (the still seeded by its own first frame).
    const uint32_t seed = below > 0 ? 1 : 7;
    const std::vector<Image> plain = plain_averages(recs, seed, 6);
    for (auto& f : frames) CAF_CHECK(decoded(f).rgba == through_jpeg(plain[f.samples - 1]).rgba);
  }
}

CAF_TEST(a refining still traces the node still AO rays after its requested frame and none with AO off) {
  settings->refine_samples = 4;
  settings->denoise_below_db = 0;  // plain averages, compared exactly
  auto mu = std::make_shared<std::mutex>();
  auto logged = std::make_shared<std::vector<int64_t>>();  // per frame shown, its AO rays per hit
  settings->log = [mu, logged](const Event& e) {
    if (e.kind != Ev::frame) return;
    const Json* ao = e.field("ao");
    std::lock_guard<std::mutex> lock(*mu);
    logged->push_back(ao ? ao->as_int() : -1);
  };
  std::vector<ClientRecord> recs = tiny_scene();  // the fixture's, and the corner
  for (auto& r : corner_scene()) recs.push_back(r);
  struct Case {
    const char* name;
    uint32_t still_ao, page_ao;
    std::vector<int64_t> rays;  // per frame
  };
  const std::vector<Case> cases = {
      {"the default", sampling::kStillAoSamples, 1, {1, 4, 4, 4}},
      {"two rays", 2, 1, {1, 2, 2, 2}},
      {"0: the session's", 0, 1, {1, 1, 1, 1}},
      {"AO off on the page", 2, 0, {0, 0, 0, 0}},
  };
  uint32_t frame = 0;
  for (const Case& c : cases) {
    CAF_MESSAGE(c.name);
    settings->still_ao_samples = c.still_ao;
    {
      std::lock_guard<std::mutex> lock(sink->mu);
      sink->records.clear();
    }
    {
      std::lock_guard<std::mutex> lock(*mu);
      logged->clear();
    }
    std::vector<ClientRecord> session = corner_session();
    session.push_back(protocol::Settings{c.page_ao, 4});
    client(session);
    client({RenderRequest{++frame}});
    run();
    auto frames = sink->all<Frame>();
    CAF_REQUIRE_EQUAL(frames.size(), 4u);
    {
      std::lock_guard<std::mutex> lock(*mu);
      CAF_CHECK_EQUAL(*logged, c.rays);
    }
    // Exactly the averages of such samples, seeded by the still's own first frame.
    const uint32_t seed = status().frames_started - 3;
    const std::vector<Image> plain = plain_averages(recs, seed, 4, int32_t(c.rays[0]), int32_t(c.rays[1]));
    for (auto& f : frames) CAF_CHECK(decoded(f).rgba == through_jpeg(plain[f.samples - 1]).rgba);
  }
  CAF_CHECK_EQUAL(sink->all<ErrorReply>().size(), 0u);
}

CAF_TEST(refined adaptively a still renders part of its blocks after its uniform rounds and ends converged) {
  settings->adaptive_round = 0.25;
  settings->denoise_below_db = 0;  // plain averages, so that the rounds after the fourth are adaptive
  settings->refine_samples = 12;
  auto mu = std::make_shared<std::mutex>();
  auto logged = std::make_shared<std::vector<uint32_t>>();  // per frame shown, the blocks its round rendered (0: all)
  settings->log = [mu, logged](const Event& e) {
    if (e.kind != Ev::frame) return;
    uint32_t b = 0;
    for (const auto& [key, value] : e.fields)
      if (key == "blocks") b = uint32_t(value.as_int());
    std::lock_guard<std::mutex> lock(*mu);
    logged->push_back(b);
  };
  std::vector<ClientRecord> recs = tiny_scene();  // the fixture's, and the corner
  for (auto& r : corner_scene()) recs.push_back(r);
  client(corner_session());
  client({RenderRequest{1}});
  run();
  auto frames = sink->all<Frame>();
  CAF_REQUIRE_GREATER(frames.size(), 5u);
  // The first four: every pixel, exactly the plain averages.
  const std::vector<Image> plain = plain_averages(recs, 1, 4);
  for (size_t i = 0; i < 4; ++i) {
    CAF_CHECK_EQUAL(frames[i].samples, uint32_t(i + 1));
    CAF_CHECK(decoded(frames[i]).rgba == through_jpeg(plain[i]).rgba);
  }
  // Then rounds of part of the blocks (64 blocks at 32x32): more rounds than samples, and the
  // mean samples per pixel rising to at most the target; only the last frame is converged.
  CAF_CHECK_GREATER(status().frames_started, frames.back().samples);
  for (size_t i = 1; i < frames.size(); ++i) CAF_CHECK_GREATER_OR_EQUAL(frames[i].samples, frames[i - 1].samples);
  CAF_CHECK_LESS_OR_EQUAL(frames.back().samples, 12u);
  for (size_t i = 0; i + 1 < frames.size(); ++i) CAF_CHECK(!frames[i].converged);
  CAF_CHECK(frames.back().converged);
  CAF_CHECK(frames.back().refined);
  {
    std::lock_guard<std::mutex> lock(*mu);
    CAF_REQUIRE_EQUAL(logged->size(), frames.size());
    for (size_t i = 0; i < 4; ++i) CAF_CHECK_EQUAL((*logged)[i], 0u);
    CAF_CHECK_GREATER((*logged)[4], 0u);
    CAF_CHECK_LESS((*logged)[4], 64u);
  }
  // Converged: the node is idle.
  const uint32_t started = status().frames_started;
  run();
  CAF_CHECK_EQUAL(status().frames_started, started);
  CAF_CHECK_EQUAL(sink->all<ErrorReply>().size(), 0u);
}

CAF_TEST(a still of a scene without triangles is its background and is not refined) {
  settings->refine_samples = 8;
  client({Remove{RecordType::mesh, 3}, SetCamera{camera_at(3)}, RenderRequest{1}});
  run();
  CAF_CHECK_EQUAL(status().frames_started, 1u);
  CAF_CHECK_EQUAL(last_frame().samples, 1u);
  CAF_CHECK(!last_frame().refined);
  // The scene comes back: its still refines as before.
  client(tiny_scene());
  client({RenderRequest{2}});
  run();
  CAF_CHECK_EQUAL(last_frame().frame, 2u);
  CAF_CHECK_EQUAL(last_frame().samples, 8u);
  CAF_CHECK_EQUAL(status().frames_started, 9u);
  CAF_CHECK_EQUAL(sink->all<ErrorReply>().size(), 0u);
}

CAF_TEST(a refine record from the client sets its target and 0 turns refinement off) {
  settings->refine_samples = 8;
  client({Refine{3}, SetCamera{camera_at(3)}, RenderRequest{1}});
  run();
  const Frame three = last_frame();
  CAF_CHECK_EQUAL(three.samples, 3u);
  CAF_CHECK_EQUAL(status().frames_started, 3u);
  client({Refine{0}, RenderRequest{2}});
  run();
  const Frame off = last_frame();
  CAF_CHECK_EQUAL(off.frame, 2u);
  CAF_CHECK_EQUAL(off.samples, 1u);
  CAF_CHECK_EQUAL(status().frames_started, 4u);
}

CAF_TEST(a session that ends mid frame takes all its actors with it) {
  client({SetCamera{camera_at(3)}, RenderRequest{1}});
  deliver_client();
  expect_frame_start();
  expect((scene_atom, SceneSnapshot), from(frame).to(subtree));
  expect((render_atom, RenderBatch), from(frame).to(subtree));
  // The render task is in the renderer's mailbox when the client goes away.
  self->send_exit(session, caf::exit_reason::user_shutdown);
  run();
  CAF_CHECK_EQUAL(sys.registry().running(), baseline);
  CAF_CHECK(frames_sent().empty());
}

CAF_TEST(a fatal protocol error closes only this session and ends its actors) {
  client({Handshake{}});  // a second handshake
  run();
  auto errors = sink->all<ErrorReply>();
  CAF_REQUIRE_EQUAL(errors.size(), 1u);
  CAF_CHECK(errors[0].fatal);
  CAF_CHECK_EQUAL(errors[0].code, ErrorCode::bad_handshake);
  CAF_CHECK_EQUAL(sink->closes, 1);
  CAF_CHECK_EQUAL(sys.registry().running(), baseline);
}

CAF_TEST(malformed and inconsistent messages get errors and the session keeps rendering) {
  self->send(session, client_atom::value, std::vector<uint8_t>{'T', 'S', protocol::kVersion, 0, 1, 0, 0, 0, 0x10});
  SetMesh bad;
  bad.id = 9;
  bad.mesh.positions = 2;  // the u32 index buffer as positions
  client({bad});
  client({SetCamera{camera_at(3)}, RenderRequest{5}});
  run();
  auto errors = sink->all<ErrorReply>();
  CAF_REQUIRE_EQUAL(errors.size(), 2u);
  CAF_CHECK(!errors[0].fatal);
  CAF_CHECK_EQUAL(errors[1].code, ErrorCode::bad_mesh);
  CAF_CHECK_EQUAL(errors[1].record, 0u);
  CAF_CHECK_EQUAL(frames_sent(), std::vector<uint32_t>{5});
}

CAF_TEST(a setting that changes nothing on the scene is said once as a notice and the frames render as asked) {
  // tiny_scene has no sky or ambient light: its AO rays would occlude nothing.
  client({protocol::Settings{4, 2}, SetCamera{camera_at(3)}, RenderRequest{1}});
  run();
  client({RenderRequest{2}});
  run();
  CAF_CHECK_EQUAL(frames_sent(), (std::vector<uint32_t>{1, 2}));
  auto notices = sink->all<ErrorReply>();
  CAF_REQUIRE_EQUAL(notices.size(), 1u);
  CAF_CHECK_EQUAL(notices[0].code, ErrorCode::no_effect);
  CAF_CHECK(!notices[0].fatal);
  CAF_CHECK(notices[0].message.find("ao-samples 4 has no effect") != std::string::npos);
  CAF_CHECK_EQUAL(sink->closes, 0);
  // With a sky the same setting matters: nothing more is said.
  SetEnvironment env;
  env.environment.ambient = {0.5f, 0.5f, 0.5f};
  client({env, RenderRequest{3}});
  run();
  CAF_CHECK_EQUAL(sink->all<ErrorReply>().size(), 1u);
  CAF_CHECK_EQUAL(frames_sent(), (std::vector<uint32_t>{1, 2, 3}));
}

CAF_TEST(the node budget holds the scene and refuses only the update that would cross it) {
  CAF_CHECK_EQUAL(budget->used(), 72u);  // tiny_scene's buffers
  // Other clients hold all but 300 bytes of the node's budget.
  const uint64_t others = budget->limit() - budget->used() - 300;
  budget->acquire(others);
  // A message with a buffer that fits, one that does not, and a camera: only the second is
  // refused (not fatal), the rest is applied.
  client({floats(10, 50), floats(11, 100), SetCamera{camera_at(5)}});
  run();
  auto errors = sink->all<ErrorReply>();
  CAF_REQUIRE_EQUAL(errors.size(), 1u);
  CAF_CHECK_EQUAL(errors[0].code, ErrorCode::limit_exceeded);
  CAF_CHECK(!errors[0].fatal);
  CAF_CHECK_EQUAL(errors[0].record, 1u);
  CAF_CHECK(errors[0].message.find("memory budget") != std::string::npos);
  CAF_CHECK_EQUAL(budget->used(), others + 72 + 200);
  // A deflated buffer declaring 4 MB (a few KB on the wire, its checksum broken): refused
  // from its declared size, before it is inflated (else: bad_payload).
  auto bomb = encode(ClientRecord{[] {
    SetBuffer b = floats(12, 1u << 20);
    b.deflate = true;
    return b;
  }()});
  CAF_REQUIRE(bomb.size() < 64u << 10);
  bomb[bomb.size() - 1] ^= 0xff;
  self->send(session, client_atom::value, bomb);
  run();
  errors = sink->all<ErrorReply>();
  CAF_REQUIRE_EQUAL(errors.size(), 2u);
  CAF_CHECK_EQUAL(errors[1].code, ErrorCode::limit_exceeded);
  CAF_CHECK(!errors[1].fatal);
  // The session goes on: it renders, and what it frees can be used again.
  client({RenderRequest{7}});
  run();
  CAF_CHECK_EQUAL(frames_sent(), std::vector<uint32_t>{7});
  // (A message's payloads need room beside what the session holds: they are reserved before
  // it is decoded, so a removal frees its bytes for the next message.)
  client({Remove{RecordType::buffer, 10}});
  client({floats(11, 70)});
  run();
  CAF_CHECK_EQUAL(sink->all<ErrorReply>().size(), 2u);
  CAF_CHECK_EQUAL(budget->used(), others + 72 + 280);
  budget->release(others);
}

CAF_TEST(updates cached while a frame renders count in the node budget and a session returns its bytes) {
  client({SetCamera{camera_at(3)}, RenderRequest{1}});
  deliver_client();
  CAF_CHECK(status().in_flight);
  client({floats(20, 100)});
  deliver_client();
  CAF_CHECK_EQUAL(status().cached_updates, 1u);
  CAF_CHECK_EQUAL(budget->used(), 72u + 400);
  run();
  CAF_CHECK_EQUAL(status().cached_updates, 0u);
  CAF_CHECK_EQUAL(budget->used(), 72u + 400);  // now in the scene
  self->send_exit(session, caf::exit_reason::user_shutdown);
  run();
  CAF_CHECK_EQUAL(budget->used(), 0u);
}

CAF_TEST_FIXTURE_SCOPE_END()

namespace {

// A session without a handshake yet.
struct bare_fixture : test_coordinator_fixture<TestConfig> {
  std::shared_ptr<RecordingSink> sink = std::make_shared<RecordingSink>();
  std::shared_ptr<NodeSettings> settings = std::make_shared<NodeSettings>();
  session_actor session;
  size_t baseline = 0;
  bare_fixture() {
    settings->detached = false;
    settings->packet_layout = {4, 4};
    settings->log = [](const Event&) {};
    settings->handshake_timeout_ms = 300;
    run();
    baseline = sys.registry().running();
  }
  void open() {
    session = spawn_session(sys, sink, settings, 1);
    sched.run();  // not the timeout
  }
  void check_closed_with_bad_handshake() {
    auto errors = sink->all<ErrorReply>();
    CAF_REQUIRE_EQUAL(errors.size(), 1u);
    CAF_CHECK(errors[0].fatal);
    CAF_CHECK_EQUAL(errors[0].code, ErrorCode::bad_handshake);
    CAF_CHECK_EQUAL(sink->closes, 1);
    CAF_CHECK_EQUAL(sys.registry().running(), baseline);
  }
};

}  // namespace

CAF_TEST_FIXTURE_SCOPE(handshake_tests, bare_fixture)

CAF_TEST(a session without a handshake is closed after the handshake timeout) {
  open();
  CAF_CHECK_EQUAL(sink->closes, 0);
  sched.advance_time(std::chrono::milliseconds(299));
  sched.run();
  CAF_CHECK_EQUAL(sink->closes, 0);
  sched.advance_time(std::chrono::milliseconds(1));
  sched.run();
  check_closed_with_bad_handshake();
  CAF_CHECK(sink->all<ErrorReply>()[0].message.find("300 ms") != std::string::npos);
}

CAF_TEST(a handshake in time is not closed by the timeout) {
  open();
  Handshake hs;
  hs.width = 16;
  hs.height = 16;
  self->send(session, client_atom::value, encode(std::vector<ClientRecord>{hs}));
  sched.run();
  sched.advance_time(std::chrono::milliseconds(1000));
  sched.run();
  CAF_CHECK_EQUAL(sink->closes, 0);
  CAF_CHECK_EQUAL(sink->all<HandshakeReply>().size(), 1u);
  self->send_exit(session, caf::exit_reason::user_shutdown);
  sched.run();
}

CAF_TEST(a first message that does not decode ends the session with bad_handshake) {
  open();
  auto bytes = encode(std::vector<ClientRecord>{Handshake{}});
  bytes[8 + 8] = 7;  // renderer: no such enum value
  self->send(session, client_atom::value, bytes);
  sched.run();
  check_closed_with_bad_handshake();
  CAF_CHECK(sink->all<ErrorReply>()[0].message.find("bad_enum") != std::string::npos);
}

CAF_TEST_FIXTURE_SCOPE_END()

namespace {

// A session whose client asked for H.264 frames.
struct video_fixture : fixture {
  video_fixture() : fixture(DisplayKind::h264) {}
  bool keyframe(const Frame& f) {
    const auto t = h264_nal_types(f.payload.data(), f.payload.size());
    return std::find(t.begin(), t.end(), 5) != t.end();
  }
};

}  // namespace

CAF_TEST_FIXTURE_SCOPE(video_tests, video_fixture)

CAF_TEST(an H.264 frame waits until the connection has written the last one and the newest wins) {
  // The connection still holds a frame: the display renders on, but encodes nothing (an H.264
  // frame must never be replaced at the connection, so it is dropped before encoding instead).
  sink->unsent = 1;
  client({SetCamera{camera_at(3)}, RenderRequest{1}});
  run();
  for (uint32_t f : {2u, 3u}) {
    client({SetCamera{camera_at(3.f + 0.1f * float(f))}, RenderRequest{f}});
    run();
  }
  CAF_CHECK_EQUAL(frames_sent(), std::vector<uint32_t>{});
  // Written: the newest frame goes, as the stream's keyframe, and decodes.
  sink->unsent = 0;
  CAF_REQUIRE(sink->gone);
  sink->gone();
  run();
  CAF_REQUIRE_EQUAL(frames_sent(), std::vector<uint32_t>{3});
  Frame f3 = last_frame();
  CAF_CHECK_EQUAL(f3.encoding, FrameEncoding::h264);
  CAF_CHECK(keyframe(f3));
  H264Decoder dec;
  Image img;
  std::string err;
  CAF_CHECK(dec.decode(f3.payload.data(), f3.payload.size(), img, err, 16, 16));
  // With the connection free, the next frame goes at once, predicted from the last one.
  client({SetCamera{camera_at(3.5f)}, RenderRequest{4}});
  run();
  CAF_REQUIRE_EQUAL(frames_sent(), (std::vector<uint32_t>{3, 4}));
  Frame f4 = last_frame();
  CAF_CHECK(!keyframe(f4));
  CAF_CHECK(dec.decode(f4.payload.data(), f4.payload.size(), img, err, 16, 16));
  // A keyframe when the client asks for one (its decoder lost its place).
  client({Video{0, true}, RenderRequest{5}});
  run();
  CAF_REQUIRE_EQUAL(frames_sent(), (std::vector<uint32_t>{3, 4, 5}));
  CAF_CHECK(keyframe(last_frame()));
  CAF_CHECK_EQUAL(sink->all<ErrorReply>().size(), 0u);
}

CAF_TEST_FIXTURE_SCOPE_END()
