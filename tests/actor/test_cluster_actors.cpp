// Deterministic tests of the cluster paths (actors/subtree*.cpp, actors/node_actor.cpp) with CAF's
// test coordinator: a session whose node has children, some of them real node actors with
// real workers and renderers, some of them fakes that lie, hang, die or straggle. Every
// message runs on the test's one thread, timeouts fire only when the test says so.
#define CAF_SUITE cluster_actors
#include <caf/test/dsl.hpp>
#include <caf/test/unit_test_impl.hpp>

#include <algorithm>
#include <chrono>
#include <functional>
#include <memory>
#include <thread>

#include <cmath>
#include <cstring>
#include <limits>

#include "actors/node.h"
#include "actors/checks.h"
#include "renderer/renderer.h"
#include "actors/subtree_state.h"
#include "protocol/protocol.h"
#include "protocol/scene_records.h"
#include "lb/sat.h"
#include "tests/actor/actor_helpers.h"

using namespace tessera;
using namespace tessera::protocol;
using namespace tessera::test;

namespace {

constexpr int kSize = 16;

// What a fake child does with its tasks.
// late: holds its batches until the test releases them, and answers pings meanwhile.
// stops: every tile says it stopped early (TileResult::cancelled), asked or not.
enum class Mode { liar, hang, straggler, bad_info, slow_acks, late, stops, noisy };

struct FakeLog {
  std::vector<RenderBatch> batches;
  size_t updates = 0;      // whole updates (the last chunk of each)
  size_t chunks = 0;       // update chunks received
  size_t chunk_bytes = 0;  // their bytes
  size_t plain_bytes = 0;  // bytes of whole updates sent as one plain message
  size_t max_chunk = 0;    // the largest chunk
  std::vector<std::string> order;  // "u" per whole update, "b" per batch, as they arrived
  size_t pings = 0;
  std::vector<caf::response_promise> held;
  std::vector<std::pair<caf::typed_response_promise<BatchReply>, RenderBatch>> held_batches;  // late
  std::vector<caf::typed_response_promise<uint64_t>> held_acks;  // slow_acks: not yet acknowledged
  std::vector<uint64_t> held_ack_sizes;  // hang: never answered
  std::vector<uint32_t> cancels;         // the frames its parent abandoned (cancel)
};

// Tiles for every task of `b`: valid pixels, and a cost map that says every packet costs 1 ms
// (a node on a CPU shared with something else); a liar's have the wrong size.
BatchReply reply_for(const RenderBatch& b, Mode mode, bool stopped = false) {
  BatchReply r;
  for (const Rect& task : b.tasks) {
    TileResult t;
    t.frame = b.frame;
    t.pixels = task;
    t.cancelled = stopped || mode == Mode::stops;
    if (t.cancelled) {  // its figures alone (check_tile)
      r.tiles.push_back(std::move(t));
      continue;
    }
    if (b.radiance) t.radiance.assign(size_t(task.area()) * 12, 0);
    if (b.radiance && mode == Mode::noisy)  // a still whose samples disagree: a value in [0, 1) per pixel and frame
      for (size_t i = 0; i < size_t(task.area()) * 3; ++i) {
        const float v = float((b.frame * 2654435761u + uint32_t(i / 3) * 40503u) % 1000u) / 1000.0f;
        std::memcpy(t.radiance.data() + i * 4, &v, 4);
      }
    if (mode == Mode::liar) {
      t.rgba.assign(7, 0);  // not width x height x 4
    } else {
      t.rgba.assign(size_t(task.area()) * 4, 128);
      CostMap cm;
      cm.packets = {task.x0 / 2, task.y0 / 2, (task.x1 + 1) / 2, (task.y1 + 1) / 2};
      cm.cost.assign(size_t(cm.packets.area()), 1'000'000);
      Sat::from_cost_map(cm).serialize_into(t.sat);
      t.kernel_ms = double(cm.packets.area());
    }
    r.tiles.push_back(std::move(t));
  }
  return r;
}

// A worker that answers (or not) as its mode says; one node named `name`.
subtree_actor::behavior_type fake_worker(subtree_actor::pointer self, Mode mode, std::shared_ptr<FakeLog> log) {
  return {
      [=](update_atom, Payload& payload, bool reset) {
        auto& bytes = payload.bytes;
        if (!bytes.empty() || reset) log->updates++;  // not the adoption notice
        log->plain_bytes += bytes.size();
      },
      [=](update_atom, Payload& chunk, bool, bool last) -> caf::result<uint64_t> {
        log->chunks++;
        log->chunk_bytes += chunk.bytes.size();
        log->max_chunk = std::max(log->max_chunk, chunk.bytes.size());
        if (last) {
          log->updates++;
          log->order.push_back("u");
        }
        if (mode == Mode::slow_acks) {  // acknowledged when the test says so
          log->held_acks.push_back(self->make_response_promise<uint64_t>());
          log->held_ack_sizes.push_back(chunk.bytes.size());
          return caf::delegated<uint64_t>{};
        }
        return uint64_t(chunk.bytes.size());
      },
      [=](render_atom, RenderBatch& b) -> caf::result<BatchReply> {
        log->batches.push_back(b);
        log->order.push_back("b");
        if (mode == Mode::hang) {
          log->held.push_back(self->make_response_promise());
          return caf::delegated<BatchReply>{};
        }
        if (mode == Mode::late) {
          log->held_batches.emplace_back(self->make_response_promise<BatchReply>(), b);
          return caf::delegated<BatchReply>{};
        }
        return reply_for(b, mode);
      },
      [=](nodes_atom) {
        // bad_info: a node that claims an impossible coefficient (it would get all the work).
        return std::vector<NodeInfo>{mode == Mode::bad_info ? NodeInfo{"fake", -3, 1e300} : NodeInfo{"fake", 1, 1.0}};
      },
      [=](scene_atom, SceneSnapshot&) {},
      [=](ping_atom) -> caf::result<uint64_t> {
        log->pings++;
        if (mode == Mode::hang) {  // hung: no answer to anything
          log->held.push_back(self->make_response_promise());
          return caf::delegated<uint64_t>{};
        }
        return uint64_t(0);
      },
      [=](deadline_atom, uint64_t, uint64_t) {},
      [=](cancel_atom, uint32_t frame) { log->cancels.push_back(frame); },
      [=](tick_atom) {
        auto batches = std::move(log->held_batches);  // late: its batches answered now (stopped
        log->held_batches.clear();                    // early where their frame was abandoned)
        for (auto& [promise, b] : batches) {
          const bool stopped = std::find(log->cancels.begin(), log->cancels.end(), b.frame) != log->cancels.end();
          promise.deliver(reply_for(b, Mode::straggler, stopped));
        }
        auto acks = std::move(log->held_acks);
        auto sizes = std::move(log->held_ack_sizes);
        log->held_acks.clear();
        log->held_ack_sizes.clear();
        for (size_t i = 0; i < acks.size(); ++i) acks[i].deliver(sizes[i]);
      },
  };
}

// A node that opens fake workers.
node_actor::behavior_type fake_node(node_actor::pointer self, Mode mode, std::shared_ptr<FakeLog> log,
                                    std::shared_ptr<subtree_actor> last) {
  return {
      [=](open_atom, const OpenRequest&) {
        *last = self->spawn<caf::linked>(fake_worker, mode, log);  // ends with its node
        return OpenReply{caf::actor_cast<caf::actor>(*last), {NodeInfo{"fake", 1, 1.0}}};
      },
      [=](links_atom) { return std::vector<ChildLink>{}; },
      [=](tick_atom) {},
  };
}

// A node that is connected but never answers an open: its link was cut and the connection has
// not noticed (the requests wait in the socket).
node_actor::behavior_type deaf_node(node_actor::pointer self, std::shared_ptr<FakeLog> log) {
  return {
      [=](open_atom, const OpenRequest&) -> caf::result<OpenReply> {
        log->held.push_back(self->make_response_promise());
        return caf::delegated<OpenReply>{};
      },
      [=](links_atom) { return std::vector<ChildLink>{}; },
      [=](tick_atom) {},
  };
}

// The master's own node: its children are whatever the test put in `links`.
node_actor::behavior_type parent_node(node_actor::pointer, std::shared_ptr<std::vector<ChildLink>> links) {
  return {
      [=](open_atom, const OpenRequest&) -> OpenReply { return {}; },
      [=](links_atom) { return *links; },
      [=](tick_atom) {},
  };
}

struct fixture : test_coordinator_fixture<TestConfig> {
  std::shared_ptr<RecordingSink> sink = std::make_shared<RecordingSink>();
  std::shared_ptr<NodeSettings> settings = std::make_shared<NodeSettings>();
  std::shared_ptr<std::vector<ChildLink>> links = std::make_shared<std::vector<ChildLink>>();
  std::vector<Event> events;  // what the session and the workers reported, through the logger
  logger_actor logger;
  node_actor parent;
  session_actor session;
  std::vector<caf::actor> nodes;  // the children's node actors (ended with the test)

  fixture() {
    settings->detached = false;
    settings->packet_layout = {2, 2};
    settings->task_timeout_ms = 1000;
    settings->log = [this](const Event& e) {
      if (getenv("TESSERA_TEST_VERBOSE")) fprintf(stderr, "%s\n", to_json_line(e).c_str());
      events.push_back(e);
    };
    logger = spawn_logger(sys, settings->log);
    settings->logger = caf::actor_cast<caf::weak_actor_ptr>(logger);
    parent = sys.spawn(parent_node, links);
    settings->node = caf::actor_cast<caf::weak_actor_ptr>(parent);
  }
  ~fixture() override {
    if (session) self->send_exit(session, caf::exit_reason::user_shutdown);
    self->send_exit(parent, caf::exit_reason::user_shutdown);
    for (auto& n : nodes) self->send_exit(n, caf::exit_reason::user_shutdown);
    sched.run();
  }
  void add_child(const std::string& name, caf::actor node) {
    nodes.push_back(node);
    links->push_back(ChildLink{name, std::move(node)});
  }
  // Opens the session (it opens workers on the children), handshakes and uploads.
  void start() {
    session = spawn_session(sys, sink, settings, 1);
    sched.run();
    Handshake hs;
    hs.width = kSize;
    hs.height = kSize;
    self->send(session, client_atom::value, encode(std::vector<ClientRecord>{hs}));
    self->send(session, client_atom::value, encode(tiny_scene()));
    sched.run();
  }
  // (sched.run() delivers messages only: the fixture's run() also fires timeouts, and the
  // periodic reconnect ticks would never end.)
  void request_frame(uint32_t n) {
    self->send(session, client_atom::value, encode(std::vector<ClientRecord>{SetCamera{camera_at(3)}, RenderRequest{n}}));
  }
  std::vector<uint32_t> frames_sent() {
    std::vector<uint32_t> out;
    for (auto& f : sink->all<Frame>()) out.push_back(f.frame);
    return out;
  }
  // Events of `kind` (for which `pred` holds) reported so far.
  size_t count(Ev kind, const std::function<bool(const Event&)>& pred = nullptr) {
    size_t n = 0;
    for (auto& e : events) n += e.kind == kind && (!pred || pred(e));
    return n;
  }
  // Events of `kind` whose own value is `value`.
  size_t count(Ev kind, const Json& value) {
    return count(kind, [&](const Event& e) { return e.value == value; });
  }
};

}  // namespace

CAF_TEST_FIXTURE_SCOPE(cluster_tests, fixture)

CAF_TEST(a real child node renders its share and gets every accepted scene record) {
  auto child_settings = std::make_shared<NodeSettings>(*settings);
  child_settings->node = {};
  child_settings->name = "child";
  auto child = spawn_node(sys, child_settings);
  add_child("child:1", caf::actor_cast<caf::actor>(child));
  start();
  auto replies = sink->all<HandshakeReply>();
  CAF_REQUIRE_EQUAL(replies.size(), 1u);
  CAF_CHECK_EQUAL(replies[0].nodes, 2u);  // this node and the child
  request_frame(1);
  sched.run();
  CAF_CHECK_EQUAL(frames_sent(), std::vector<uint32_t>{1});
  CAF_CHECK_EQUAL(count(Ev::recovering), 0u);
  CAF_CHECK_EQUAL(count(Ev::cluster_frame, 1), 1u);
  CAF_CHECK_EQUAL(sink->all<ErrorReply>().size(), 0u);
}

CAF_TEST(a big update goes down in chunks within the window and the batch of the frame waits behind it) {
  auto log = std::make_shared<FakeLog>();
  auto last = std::make_shared<subtree_actor>();
  add_child("slow:1", caf::actor_cast<caf::actor>(sys.spawn(fake_node, Mode::slow_acks, log, last)));
  auto release_acks = [&] {  // the fake worker acknowledges what it holds on a tick
    const size_t n = log->held_acks.size();
    if (n > 0) {
      self->send(*last, tick_atom::value);
      sched.run();
    }
    return n;
  };
  start();
  while (release_acks() > 0) {
  }
  CAF_REQUIRE_EQUAL(log->updates, 2u);  // the snapshot at join, then the uploaded records
  const size_t before = log->chunk_bytes;
  // 3 MiB of vertex data: 12 chunks of 256 KiB and some.
  SetBuffer big;
  big.id = 50;
  big.buffer.type = Buffer::Type::f32;
  big.buffer.components = 3;
  big.buffer.f.assign(3 * 262144, 0.5f);
  self->send(session, client_atom::value, encode(std::vector<ClientRecord>{big}));
  request_frame(1);
  sched.run();
  // Nothing acknowledged yet: exactly one window went down, and the batch waits.
  CAF_CHECK_EQUAL(log->chunk_bytes - before, kUpdateWindowBytes);
  CAF_CHECK_EQUAL(log->max_chunk, kUpdateChunkBytes);
  CAF_CHECK_EQUAL(log->batches.size(), 0u);
  CAF_CHECK(frames_sent().empty());
  size_t rounds = 0;
  while (release_acks() > 0) ++rounds;
  CAF_CHECK_GREATER_OR_EQUAL(rounds, 3u);  // a window at a time
  CAF_CHECK_GREATER(log->chunk_bytes - before, 3u * 262144u * 4u);
  CAF_CHECK_EQUAL(log->updates, 4u);  // + the big buffer, + the camera of the frame
  CAF_REQUIRE_EQUAL(log->batches.size(), 1u);
  CAF_CHECK_EQUAL(log->order.back(), "b");  // after the update it renders
  CAF_CHECK_EQUAL(log->order[log->order.size() - 2], "u");
  CAF_CHECK_EQUAL(frames_sent(), std::vector<uint32_t>{1});
  CAF_CHECK_EQUAL(sink->all<ErrorReply>().size(), 0u);
}

CAF_TEST(small updates go as plain messages while less than a chunk is unacknowledged and then through the window) {
  auto log = std::make_shared<FakeLog>();
  auto last = std::make_shared<subtree_actor>();
  add_child("slow:1", caf::actor_cast<caf::actor>(sys.spawn(fake_node, Mode::slow_acks, log, last)));
  start();
  const size_t plain_at_start = log->plain_bytes;  // the snapshot and the upload: small
  CAF_CHECK_GREATER(plain_at_start, 0u);
  CAF_CHECK_EQUAL(log->chunks, 0u);
  // 2 MiB in 4 KiB updates, none acknowledged: a chunk's worth goes plain, then one window of
  // acknowledged ones, and the rest waits.
  for (Id i = 0; i < 512; ++i) {
    SetBuffer b;
    b.id = 100 + i;
    b.buffer.type = Buffer::Type::f32;
    b.buffer.components = 1;
    b.buffer.f.assign(1000, 0.5f);
    self->send(session, client_atom::value, encode(std::vector<ClientRecord>{b}));
  }
  sched.run();
  CAF_CHECK_LESS_OR_EQUAL(log->plain_bytes, kUpdateChunkBytes);
  CAF_CHECK_GREATER(log->chunks, 0u);
  CAF_CHECK_LESS_OR_EQUAL(log->plain_bytes + log->chunk_bytes, kUpdateChunkBytes + kUpdateWindowBytes);
  // Acknowledged, everything arrives.
  for (int round = 0; round < 1000 && !log->held_acks.empty(); ++round) {
    self->send(*last, tick_atom::value);
    sched.run();
  }
  CAF_CHECK_EQUAL(log->updates, 2u + 512u);
  CAF_CHECK_EQUAL(sink->all<ErrorReply>().size(), 0u);
}

CAF_TEST(tiles with impossible sizes are rejected and logged and the master renders that task) {
  auto log = std::make_shared<FakeLog>();
  auto last = std::make_shared<subtree_actor>();
  add_child("liar:1", caf::actor_cast<caf::actor>(sys.spawn(fake_node, Mode::liar, log, last)));
  start();
  CAF_CHECK_EQUAL(log->updates, 2u);  // the snapshot at join, then the uploaded records
  request_frame(1);
  sched.run();
  CAF_CHECK_EQUAL(frames_sent(), std::vector<uint32_t>{1});
  CAF_CHECK_EQUAL(count(Ev::rejected_tile, "liar:1"), 1u);
  CAF_CHECK_EQUAL(count(Ev::recovering, 1), 1u);
  CAF_CHECK_EQUAL(sink->all<ErrorReply>().size(), 0u);
}

CAF_TEST(a child that dies mid frame: the frame completes and the next one is tiled among the rest) {
  auto log = std::make_shared<FakeLog>();
  auto last = std::make_shared<subtree_actor>();
  add_child("hang:1", caf::actor_cast<caf::actor>(sys.spawn(fake_node, Mode::hang, log, last)));
  start();
  request_frame(1);
  sched.run();
  CAF_REQUIRE_EQUAL(log->batches.size(), 1u);  // it got its task and holds it
  CAF_CHECK(frames_sent().empty());            // the frame waits for it
  self->send_exit(*last, caf::exit_reason::kill);
  sched.run();
  CAF_CHECK_EQUAL(frames_sent(), std::vector<uint32_t>{1});
  CAF_CHECK_EQUAL(count(Ev::node_lost, "hang:1"), 1u);
  request_frame(2);
  sched.run();
  CAF_CHECK_EQUAL(frames_sent(), (std::vector<uint32_t>{1, 2}));
  CAF_CHECK_EQUAL(count(Ev::nodes, [](const Event& e) { return *e.field("used") == Json(1); }), 1u);  // committed without it before frame 2
}

CAF_TEST(a child that is alive but never answers is failed by the timeout and its tiles rendered here) {
  auto log = std::make_shared<FakeLog>();
  auto last = std::make_shared<subtree_actor>();
  add_child("hang:2", caf::actor_cast<caf::actor>(sys.spawn(fake_node, Mode::hang, log, last)));
  start();
  request_frame(1);
  sched.run();
  CAF_CHECK(frames_sent().empty());
  sched.trigger_timeouts();  // the part's deadline: late, rendered here, and a ping goes out
  sched.run();
  CAF_CHECK_EQUAL(frames_sent(), std::vector<uint32_t>{1});
  CAF_CHECK_EQUAL(count(Ev::recovering, 1), 1u);
  CAF_CHECK_EQUAL(count(Ev::node_late, "hang:2"), 1u);
  CAF_CHECK_EQUAL(log->pings, 1u);
  CAF_CHECK_EQUAL(count(Ev::node_lost, "hang:2"), 0u);
  // It does not answer the ping either: lost (and, its node still answering opens, opened
  // again). The next frame does not wait for the lost one: its part is rendered here at once.
  sched.trigger_timeouts();
  sched.run();
  CAF_CHECK_EQUAL(count(Ev::node_lost, [](const Event& e) {
                    return e.value == Json("hang:2") && e.field("reason")->as_string().find("no answer to a ping") != std::string::npos;
                  }),
                  1u);
  request_frame(2);
  sched.run();
  CAF_CHECK_EQUAL(frames_sent(), (std::vector<uint32_t>{1, 2}));
  CAF_CHECK_EQUAL(count(Ev::recovering, 1), 2u);
}

CAF_TEST(a late child that still answers is kept: its tiles are rendered here until it catches up) {
  auto log = std::make_shared<FakeLog>();
  auto last = std::make_shared<subtree_actor>();
  add_child("late:1", caf::actor_cast<caf::actor>(sys.spawn(fake_node, Mode::late, log, last)));
  start();
  request_frame(1);
  sched.run();
  CAF_REQUIRE_EQUAL(log->batches.size(), 1u);
  CAF_CHECK(frames_sent().empty());
  sched.trigger_timeouts();  // the deadline: the frame goes out with the child's part rendered here
  sched.run();
  CAF_CHECK_EQUAL(frames_sent(), std::vector<uint32_t>{1});
  CAF_CHECK_EQUAL(count(Ev::node_late, "late:1"), 1u);
  CAF_CHECK_EQUAL(log->pings, 1u);  // and it answered
  // While it is late it gets no tasks, and frames do not wait for it.
  request_frame(2);
  sched.run();
  CAF_CHECK_EQUAL(frames_sent(), (std::vector<uint32_t>{1, 2}));
  CAF_CHECK_EQUAL(log->batches.size(), 1u);
  CAF_CHECK_EQUAL(count(Ev::recovering, 1), 2u);
  // Its late reply arrives (and is dropped): it is on time again, and the next frame uses it.
  self->send(*last, tick_atom::value);
  sched.run();
  CAF_CHECK_EQUAL(count(Ev::caught_up, "late:1"), 1u);
  request_frame(3);
  sched.run();
  CAF_CHECK_EQUAL(log->batches.size(), 2u);
  CAF_CHECK_EQUAL(log->held_batches.size(), 1u);
  self->send(*last, tick_atom::value);
  sched.run();
  CAF_CHECK_EQUAL(frames_sent(), (std::vector<uint32_t>{1, 2, 3}));
  CAF_CHECK_EQUAL(count(Ev::recovering, 1), 2u);  // frame 3 was composed with it
  // Never lost, so never opened again with the whole scene.
  CAF_CHECK_EQUAL(count(Ev::node_lost), 0u);
  CAF_CHECK_EQUAL(count(Ev::joined, "late:1"), 1u);
}

CAF_TEST(a render request during a still sample abandons it: the children are told and the sample is neither averaged nor shown) {
  settings->refine_samples = 8;
  auto log = std::make_shared<FakeLog>();
  auto last = std::make_shared<subtree_actor>();
  add_child("late:1", caf::actor_cast<caf::actor>(sys.spawn(fake_node, Mode::late, log, last)));
  start();
  request_frame(1);
  sched.run();
  CAF_REQUIRE_EQUAL(log->batches.size(), 1u);
  self->send(*last, tick_atom::value);  // the child answers: frame 1 is shown
  sched.run();
  CAF_CHECK_EQUAL(frames_sent(), std::vector<uint32_t>{1});
  // The still's next sample is on its way: its batch waits at the child.
  CAF_REQUIRE_EQUAL(log->batches.size(), 2u);
  CAF_CHECK_EQUAL(log->batches[1].sample, 1u);
  CAF_CHECK(log->batches[1].radiance);
  CAF_CHECK(log->cancels.empty());
  request_frame(2);
  sched.run();
  CAF_CHECK_EQUAL(log->cancels, std::vector<uint32_t>{log->batches[1].frame});
  self->send(*last, tick_atom::value);  // its tiles come back stopped early
  sched.run();
  CAF_CHECK_EQUAL(count(Ev::abandoned, 1), 1u);
  CAF_CHECK_EQUAL(count(Ev::abandoned, [](const Event& e) { const Json* n = e.field("tiles_stopped"); return n && *n == Json(1); }), 1u);
  // Frame 2 started at once, and renders where frame 1 did: nothing was recovered here.
  CAF_REQUIRE_EQUAL(log->batches.size(), 3u);
  CAF_CHECK_EQUAL(log->batches[2].sample, 0u);
  self->send(*last, tick_atom::value);
  sched.run();
  CAF_CHECK_EQUAL(frames_sent(), (std::vector<uint32_t>{1, 2}));
  for (const Frame& f : sink->all<Frame>()) CAF_CHECK(!f.refined);  // the sample of frame 1 was never shown
  CAF_CHECK_EQUAL(count(Ev::recovering), 0u);
  CAF_CHECK_EQUAL(sink->all<ErrorReply>().size(), 0u);
  // Frame 2's own still goes on: its sample 1 is asked of the child, and nothing cancels it.
  CAF_REQUIRE_EQUAL(log->batches.size(), 4u);
  CAF_CHECK_EQUAL(log->batches[3].sample, 1u);
  CAF_CHECK_EQUAL(log->cancels.size(), 1u);
}

CAF_TEST(an adaptive round sends each child the part of the plan its tasks need and the still ends converged) {
  settings->refine_samples = 8;
  settings->adaptive_round = 0.5;
  settings->denoise_below_db = 0;
  auto log = std::make_shared<FakeLog>();
  auto last = std::make_shared<subtree_actor>();
  add_child("noisy:1", caf::actor_cast<caf::actor>(sys.spawn(fake_node, Mode::noisy, log, last)));
  start();
  request_frame(1);
  sched.run();
  CAF_REQUIRE_GREATER(log->batches.size(), 5u);
  for (size_t i = 0; i < 4; ++i) CAF_CHECK(log->batches[i].plan.empty());  // the uniform rounds
  size_t partial = 0;
  for (size_t i = 4; i < log->batches.size(); ++i) {
    const RenderBatch& b = log->batches[i];
    CAF_CHECK(b.radiance);
    if (b.plan.empty()) continue;
    ++partial;
    CAF_REQUIRE_EQUAL(b.tasks.size(), 1u);
    CAF_CHECK_EQUAL(b.plan_blocks, plan_blocks_of(b.tasks[0]));  // its task's blocks, not the frame's
    CAF_CHECK_EQUAL(b.plan.size(), size_t(b.plan_blocks.area()));
    for (uint32_t k : b.plan) CAF_CHECK(k == kSkipPacket || k <= b.sample);  // a block's own count, or skipped
    CAF_CHECK_EQUAL(check_batch(b, Limits{}), "");
  }
  CAF_CHECK_GREATER(partial, 0u);
  auto frames = sink->all<Frame>();
  CAF_REQUIRE(!frames.empty());
  CAF_CHECK(frames.back().converged);
  CAF_CHECK_LESS_OR_EQUAL(frames.back().samples, 8u);
  CAF_CHECK_EQUAL(count(Ev::recovering), 0u);
  CAF_CHECK_EQUAL(sink->all<ErrorReply>().size(), 0u);
}

CAF_TEST(a tile that stopped early in a frame nobody abandoned is the node fault and its task is rendered here) {
  auto log = std::make_shared<FakeLog>();
  auto last = std::make_shared<subtree_actor>();
  add_child("stops:1", caf::actor_cast<caf::actor>(sys.spawn(fake_node, Mode::stops, log, last)));
  start();
  request_frame(1);
  sched.run();
  CAF_CHECK_EQUAL(frames_sent(), std::vector<uint32_t>{1});
  CAF_CHECK_EQUAL(count(Ev::recovering, 1), 1u);
  CAF_CHECK_EQUAL(count(Ev::abandoned), 0u);
}

CAF_TEST(the cost maps of a straggler shift its share away in the next frame) {
  auto log = std::make_shared<FakeLog>();
  auto last = std::make_shared<subtree_actor>();
  add_child("slow:1", caf::actor_cast<caf::actor>(sys.spawn(fake_node, Mode::straggler, log, last)));
  start();
  for (uint32_t f = 1; f <= 3; ++f) {
    request_frame(f);
    sched.run();
  }
  CAF_CHECK_EQUAL(frames_sent(), (std::vector<uint32_t>{1, 2, 3}));
  CAF_REQUIRE_EQUAL(log->batches.size(), 3u);
  auto area = [&](size_t i) { return log->batches[i].tasks.at(0).area(); };
  CAF_CHECK_EQUAL(area(0), kSize * kSize / 2);  // the first frame is split by area
  // Then by cost: the region it rendered is now known to be expensive (its cost map says so),
  // so every frame moves the split into that region and its share shrinks.
  CAF_CHECK_LESS(area(1), area(0));
  CAF_CHECK_LESS(area(2), area(1));
  CAF_CHECK_EQUAL(sink->all<ErrorReply>().size(), 0u);
}

CAF_TEST(a child that claims an impossible node list is dropped and the master renders alone) {
  auto log = std::make_shared<FakeLog>();
  auto last = std::make_shared<subtree_actor>();
  add_child("boast:1", caf::actor_cast<caf::actor>(sys.spawn(fake_node, Mode::bad_info, log, last)));
  start();
  auto replies = sink->all<HandshakeReply>();
  CAF_REQUIRE_EQUAL(replies.size(), 1u);
  CAF_CHECK_EQUAL(replies[0].nodes, 1u);
  CAF_CHECK_EQUAL(count(Ev::node_lost, [](const Event& e) { return *e.field("reason") == Json("impossible node list: node fake claims -3 logical cores"); }), 1u);
  request_frame(1);
  sched.run();
  CAF_CHECK_EQUAL(frames_sent(), std::vector<uint32_t>{1});
  CAF_CHECK(log->batches.empty());
}

CAF_TEST(frames do not wait for a child whose opens are never answered) {
  auto log = std::make_shared<FakeLog>(), deaf = std::make_shared<FakeLog>();
  auto last = std::make_shared<subtree_actor>();
  add_child("slow:2", caf::actor_cast<caf::actor>(sys.spawn(fake_node, Mode::straggler, log, last)));
  add_child("deaf:1", caf::actor_cast<caf::actor>(sys.spawn(deaf_node, deaf)));
  settings->reconnect_ms = 60000;  // retries only when the test sends a tick
  start();
  // The handshake waits for the first joins, the deaf one until its timeout.
  CAF_CHECK(sink->all<HandshakeReply>().empty());
  sched.advance_time(std::chrono::milliseconds(settings->task_timeout_ms));
  sched.run();
  auto replies = sink->all<HandshakeReply>();
  CAF_REQUIRE_EQUAL(replies.size(), 1u);
  CAF_CHECK_EQUAL(replies[0].nodes, 2u);  // this node and slow:2
  CAF_CHECK_EQUAL(count(Ev::join_failed, "deaf:1"), 1u);
  // The session retries it every reconnect period; each attempt waits for the timeout. Frames
  // meanwhile must not wait for the attempt in flight (they did, a timeout per frame).
  self->send(session, tick_atom::value);
  sched.run();
  CAF_REQUIRE_EQUAL(deaf->held.size(), 2u);
  for (uint32_t f = 1; f <= 2; ++f) {
    request_frame(f);
    sched.run();
  }
  CAF_CHECK_EQUAL(frames_sent(), (std::vector<uint32_t>{1, 2}));
  CAF_CHECK_EQUAL(count(Ev::join_failed, "deaf:1"), 1u);  // still in flight
  CAF_CHECK_EQUAL(sink->all<ErrorReply>().size(), 0u);
}

CAF_TEST(a worker whose parent gave up on its open ends itself after twice the timeout of its parent) {
  OpenRequest req{7, "master", 2, 2};
  req.timeout_ms = 1;
  auto orphan = spawn_worker(sys, settings, node_actor{}, req, caf::actor_cast<caf::strong_actor_ptr>(self));
  auto adopted = spawn_worker(sys, settings, node_actor{}, req, caf::actor_cast<caf::strong_actor_ptr>(self));
  sched.run();
  self->send(adopted, update_atom::value, Payload{}, false);  // the adoption notice
  sched.run();
  sched.advance_time(std::chrono::milliseconds(2));  // 2 x 1 ms: not yet
  self->send(orphan, tick_atom::value);
  sched.run();
  CAF_CHECK_EQUAL(count(Ev::orphaned, true), 0u);
  sched.advance_time(std::chrono::milliseconds(1));  // past 2 x 1 ms on the actor clock
  self->send(orphan, tick_atom::value);
  self->send(adopted, tick_atom::value);
  sched.run();
  CAF_CHECK_EQUAL(count(Ev::orphaned, true), 1u);
  self->send_exit(adopted, caf::exit_reason::user_shutdown);
  sched.run();
}

// An actor that opens a worker on `node` as a session would, and keeps what came back.
struct Opened {
  std::vector<subtree_actor> workers;
  std::vector<std::string> errors;
};
caf::behavior opener(caf::event_based_actor* self, node_actor node, std::shared_ptr<Opened> out) {
  return {
      [=](open_atom, OpenRequest req) {
        self->request(node, caf::infinite, open_atom::value, req)
            .then([=](OpenReply& r) { out->workers.push_back(caf::actor_cast<subtree_actor>(r.worker)); },
                  [=](caf::error& e) { out->errors.push_back(to_string(e)); });
      },
  };
}

OpenRequest good_open(uint64_t session) {
  OpenRequest r{session, "master:1", 2, 2};
  r.timeout_ms = 1000;
  r.keepalive_ms = 100;
  return r;
}

CAF_TEST(a worker opened through a node ends when the actor that opened it ends) {
  settings->node = {};
  settings->name = "n";
  auto node = spawn_node(sys, settings);
  auto out = std::make_shared<Opened>();
  auto op = sys.spawn(opener, node, out);
  self->send(op, open_atom::value, good_open(5));
  sched.run();
  CAF_REQUIRE_EQUAL(out->workers.size(), 1u);
  CAF_CHECK_EQUAL(count(Ev::worker_opened, [](const Event& e) { return e.value == Json(5) && *e.field("master") == Json("master:1") && *e.field("live_workers") == Json(1); }), 1u);
  // The session (here: the opener) ends: its worker must go too. The node used to read the
  // sender after make_response_promise had taken it over, so workers watched nobody.
  self->send_exit(op, caf::exit_reason::user_shutdown);
  sched.run();
  CAF_CHECK_EQUAL(count(Ev::ended, "parent down"), 1u);
  CAF_CHECK_EQUAL(count(Ev::worker_closed, [](const Event& e) { return e.value == Json(5) && *e.field("live_workers") == Json(0); }), 1u);
  self->send_exit(node, caf::exit_reason::user_shutdown);
  sched.run();
}

CAF_TEST(a node refuses malformed opens and opens beyond max_workers) {
  settings->node = {};
  settings->name = "n";
  settings->max_workers = 2;
  auto node = spawn_node(sys, settings);
  auto out = std::make_shared<Opened>();
  auto op = sys.spawn(opener, node, out);
  auto bad = [&](auto mutate) {
    OpenRequest r = good_open(9);
    mutate(r);
    self->send(op, open_atom::value, r);
    sched.run();
  };
  bad([](OpenRequest& r) { r.session = 0; });
  bad([](OpenRequest& r) { r.master = "m\", \"forged\": \"yes"; });
  bad([](OpenRequest& r) { r.master = std::string(300, 'm'); });
  bad([](OpenRequest& r) { r.master = "a\nb"; });
  bad([](OpenRequest& r) { r.packet_w = 3; });
  bad([](OpenRequest& r) { r.packet_w = 16, r.packet_h = 16; });
  bad([](OpenRequest& r) { r.keepalive_ms = 0; });
  bad([](OpenRequest& r) { r.keepalive_ms = 1'000'000; });
  bad([](OpenRequest& r) { r.timeout_ms = 4'000'000; });
  CAF_CHECK_EQUAL(out->workers.size(), 0u);
  CAF_REQUIRE_EQUAL(out->errors.size(), 9u);
  for (auto& e : out->errors) CAF_CHECK(e.find("open refused") != std::string::npos);
  CAF_CHECK_EQUAL(count(Ev::open_refused), 9u);
  CAF_CHECK_EQUAL(std::count_if(events.begin(), events.end(), [](const Event& e) { return to_json_line(e).find("forged") != std::string::npos; }), 0);  // the name was refused, never logged
  for (uint64_t s = 1; s <= 3; ++s) self->send(op, open_atom::value, good_open(s));
  sched.run();
  CAF_CHECK_EQUAL(out->workers.size(), 2u);
  CAF_REQUIRE_EQUAL(out->errors.size(), 10u);
  CAF_CHECK(out->errors.back().find("has 2 live workers, its max-workers") != std::string::npos);
  // One ends: there is room again.
  self->send_exit(out->workers[0], caf::exit_reason::user_shutdown);
  sched.run();
  self->send(op, open_atom::value, good_open(4));
  sched.run();
  CAF_CHECK_EQUAL(out->workers.size(), 3u);
  self->send_exit(op, caf::exit_reason::user_shutdown);
  sched.run();
  CAF_CHECK_EQUAL(count(Ev::worker_closed, [](const Event& e) { return *e.field("live_workers") == Json(0); }), 1u);
  self->send_exit(node, caf::exit_reason::user_shutdown);
  sched.run();
}

CAF_TEST(a worker ends after keepalive_misses periods without a word from its parent) {
  settings->reconnect_ms = 100;  // the worker checks every 100 ms
  settings->keepalive_misses = 3;
  OpenRequest req = good_open(3);  // the parent promises something every 100 ms
  auto w = spawn_worker(sys, settings, node_actor{}, req, caf::actor_cast<caf::strong_actor_ptr>(self));
  sched.run();
  // Keep-alives (empty updates from the parent) every period: it lives on.
  for (int i = 0; i < 10; ++i) {
    self->send(w, update_atom::value, Payload{}, false);
    sched.run();
    sched.advance_time(std::chrono::milliseconds(100));
    sched.run();
  }
  CAF_CHECK_EQUAL(count(Ev::ended), 0u);
  // The parent falls silent (it was last heard 100 ms ago); messages from others do not count.
  for (int i = 0; i < 2; ++i) {
    caf::anon_send(w, update_atom::value, Payload{}, false);
    sched.advance_time(std::chrono::milliseconds(100));
    sched.run();
  }
  CAF_CHECK_EQUAL(count(Ev::ended), 0u);  // 300 ms: not more than 3 periods yet
  sched.advance_time(std::chrono::milliseconds(100));
  sched.run();
  CAF_CHECK_EQUAL(count(Ev::ended, [](const Event& e) { return e.value == Json("parent silent") && *e.field("silent_ms") == Json(400); }), 1u);
}

// A batch as a session of a 16x16 client sends it to a worker that renders one node.
RenderBatch good_batch() {
  RenderBatch b;
  b.frame = 1;
  b.width = kSize;
  b.height = kSize;
  b.ao_samples = 1;
  b.max_depth = 2;
  b.timeout_ms = 1000;
  b.tasks = {Rect{0, 0, kSize, kSize}};
  return b;
}

// A worker opened by the test (its parent) on the tiny scene, and an actor that is not its parent:
// it asks the worker for the batches the test sends it (the replies in order) and passes cancel
// notices on.
struct TestWorker {
  subtree_actor w;
  caf::actor asker;
  std::shared_ptr<std::vector<BatchReply>> replies = std::make_shared<std::vector<BatchReply>>();
};
TestWorker open_worker(fixture& f) {
  TestWorker t;
  t.w = spawn_worker(f.sys, f.settings, node_actor{}, good_open(3), caf::actor_cast<caf::strong_actor_ptr>(f.self));
  f.self->send(t.w, update_atom::value, Payload{encode(tiny_scene())}, true);
  f.sched.run();
  auto w = t.w;
  auto replies = t.replies;
  t.asker = f.sys.spawn([=](caf::event_based_actor* a) -> caf::behavior {
    return {[=](RenderBatch& b) {
              a->request(w, caf::infinite, render_atom::value, std::move(b)).then([=](BatchReply& r) { replies->push_back(r); });
            },
            [=](cancel_atom, uint32_t frame) { a->send(w, cancel_atom::value, frame); }};
  });
  return t;
}
void close_worker(fixture& f, TestWorker& t) {
  f.self->send_exit(t.asker, caf::exit_reason::user_shutdown);
  f.self->send_exit(t.w, caf::exit_reason::user_shutdown);
  f.sched.run();
}

CAF_TEST(a worker fails every tile of a batch outside the node limits and serves on) {
  settings->limits.max_width = 64;
  settings->limits.max_height = 64;
  settings->limits.max_ao_samples = 8;
  settings->limits.max_depth = 4;
  TestWorker t = open_worker(*this);
  auto& [w, asker, replies] = t;
  std::vector<std::function<void(RenderBatch&)>> bad = {
      [](RenderBatch& b) { b.width = 100000; },
      [](RenderBatch& b) { b.height = 0; },
      [](RenderBatch& b) { b.ao_samples = 100000; },
      [](RenderBatch& b) { b.ao_samples = -1; },
      [](RenderBatch& b) { b.max_depth = 100000; },
      [](RenderBatch& b) { b.renderer = 7; },
      [](RenderBatch& b) { b.timeout_ms = 0; },
      [](RenderBatch& b) { b.tasks = {Rect{0, 0, kSize + 1, kSize}}; },
      [](RenderBatch& b) { b.tasks = {Rect{-4, 0, 4, 4}}; },
      [](RenderBatch& b) { b.tasks = {Rect{0, 0, 4, 4}, Rect{4, 4, 8, 8}}; },  // 2 tasks, 1 node
      // Plans of blocks (adaptive rounds): of the wrong size, outside the frame, not covering the
      // task, for a frame that is no sample of a still.
      [](RenderBatch& b) { b.radiance = true; b.plan_blocks = {0, 0, 4, 4}; b.plan.assign(15, 0); },
      [](RenderBatch& b) { b.radiance = true; b.plan_blocks = {0, 0, 5, 4}; b.plan.assign(20, 0); },
      [](RenderBatch& b) { b.radiance = true; b.plan_blocks = {0, 0, 4, 3}; b.plan.assign(12, 0); },
      [](RenderBatch& b) { b.plan_blocks = {0, 0, 4, 4}; b.plan.assign(16, 0); },
  };
  for (auto& mutate : bad) {
    RenderBatch b = good_batch();
    mutate(b);
    self->send(asker, b);
    sched.run();
  }
  self->send(asker, good_batch());
  sched.run();
  CAF_REQUIRE_EQUAL(replies->size(), bad.size() + 1);
  for (size_t i = 0; i < bad.size(); ++i) {
    CAF_CHECK(!(*replies)[i].tiles.empty());
    for (auto& t : (*replies)[i].tiles) {
      CAF_CHECK(t.failed());
      CAF_CHECK(!t.error.empty());
      CAF_CHECK(t.rgba.empty());
    }
  }
  CAF_CHECK_EQUAL(count(Ev::bad_batch), bad.size() - 1);  // the last one is the subtree's count check
  const BatchReply& ok = replies->back();
  CAF_REQUIRE_EQUAL(ok.tiles.size(), 1u);
  CAF_CHECK(!ok.tiles[0].failed());
  CAF_CHECK_EQUAL(ok.tiles[0].rgba.size(), size_t(kSize * kSize * 4));
  close_worker(*this, t);
}

CAF_TEST(a worker refuses a scene message from a peer and renders the scene its parent sent) {
  TestWorker t = open_worker(*this);
  auto& [w, asker, replies] = t;
  // Someone hands the worker another scene (an empty one) as a root's frame actor would.
  self->send(w, scene_atom::value, SceneSnapshot{std::make_shared<const Scene>()});
  sched.run();
  CAF_CHECK_EQUAL(count(Ev::update_failed), 1u);
  self->send(asker, good_batch());
  sched.run();
  CAF_REQUIRE_EQUAL(replies->size(), 1u);
  CAF_REQUIRE_EQUAL(replies->back().tiles.size(), 1u);
  CAF_CHECK(!replies->back().tiles[0].failed());
  CAF_CHECK_EQUAL(replies->back().tiles[0].rgba.size(), size_t(kSize * kSize * 4));
  close_worker(*this, t);
}

CAF_TEST(a worker abandons a frame when its parent says so and not when anyone else does) {
  TestWorker t = open_worker(*this);
  auto& [w, asker, replies] = t;
  RenderBatch b = good_batch();
  b.frame = 5;
  self->send(asker, cancel_atom::value, uint32_t(5));  // a stranger: ignored
  sched.run();
  self->send(asker, b);
  sched.run();
  CAF_REQUIRE_EQUAL(replies->size(), 1u);
  CAF_REQUIRE_EQUAL(replies->back().tiles.size(), 1u);
  CAF_CHECK(!replies->back().tiles[0].failed());
  CAF_CHECK(!replies->back().tiles[0].cancelled);
  self->send(w, cancel_atom::value, uint32_t(6));  // its parent abandons frame 6
  sched.run();
  b.frame = 6;
  self->send(asker, b);
  b.frame = 7;  // a later frame renders whole
  self->send(asker, b);
  sched.run();
  CAF_REQUIRE_EQUAL(replies->size(), 3u);
  CAF_CHECK(replies->at(1).tiles[0].cancelled);
  CAF_CHECK(!replies->at(2).tiles[0].cancelled);
  CAF_CHECK(!replies->at(2).tiles[0].failed());
  close_worker(*this, t);
}

CAF_TEST(a worker refuses an update whose chunks add up to more than max_update_bytes and recovers on a reset) {
  settings->max_update_bytes = 1000;
  OpenRequest req = good_open(3);
  auto w = spawn_worker(sys, settings, node_actor{}, req, caf::actor_cast<caf::strong_actor_ptr>(self));
  sched.run();
  auto acks = std::make_shared<std::vector<uint64_t>>();
  auto replies = std::make_shared<std::vector<BatchReply>>();
  auto parent = sys.spawn([=](caf::event_based_actor* a) -> caf::behavior {
    return {
        [=](Payload& chunk, bool reset, bool last) {
          a->request(w, caf::infinite, update_atom::value, std::move(chunk), reset, last)
              .then([=](uint64_t n) { acks->push_back(n); });
        },
        [=](RenderBatch& b) {
          a->request(w, caf::infinite, render_atom::value, std::move(b)).then([=](BatchReply& r) { replies->push_back(r); });
        },
    };
  });
  auto chunk = [&](std::vector<uint8_t> bytes, bool reset, bool last) {
    self->send(parent, Payload{std::move(bytes)}, reset, last);
    sched.run();
  };
  // 600 + 600 bytes of one update: over the bound at the second chunk; the rest of it is
  // taken and acknowledged, and nothing of it is applied.
  chunk(std::vector<uint8_t>(600, 7), true, false);
  chunk(std::vector<uint8_t>(600, 7), true, false);
  chunk(std::vector<uint8_t>(10, 7), true, true);
  CAF_CHECK_EQUAL(*acks, (std::vector<uint64_t>{600, 600, 10}));
  CAF_CHECK_EQUAL(count(Ev::update_failed, "a scene update over 1000 bytes"), 1u);
  self->send(parent, good_batch());
  sched.run();
  CAF_REQUIRE_EQUAL(replies->size(), 1u);
  CAF_REQUIRE_EQUAL(replies->back().tiles.size(), 1u);
  CAF_CHECK_EQUAL(replies->back().tiles[0].code, ErrorCode::no_scene);
  CAF_CHECK(replies->back().tiles[0].error.find("has no valid scene") != std::string::npos);
  // A reset update within the bound, in two chunks, replaces the scene: it renders again.
  const std::vector<uint8_t> scene = encode(tiny_scene());
  CAF_REQUIRE_LESS(scene.size(), 1000u);
  const size_t half = scene.size() / 2;
  chunk(std::vector<uint8_t>(scene.begin(), scene.begin() + long(half)), true, false);
  chunk(std::vector<uint8_t>(scene.begin() + long(half), scene.end()), true, true);
  self->send(parent, good_batch());
  sched.run();
  CAF_REQUIRE_EQUAL(replies->size(), 2u);
  CAF_REQUIRE_EQUAL(replies->back().tiles.size(), 1u);
  CAF_CHECK(!replies->back().tiles[0].failed());
  CAF_CHECK_EQUAL(replies->back().tiles[0].rgba.size(), size_t(kSize * kSize * 4));
  self->send_exit(parent, caf::exit_reason::user_shutdown);
  self->send_exit(w, caf::exit_reason::user_shutdown);
  sched.run();
}

CAF_TEST_FIXTURE_SCOPE_END()

// Log lines carry names and messages from clients and peers: they must stay one JSON object.
CAF_TEST(json_quote escapes what could forge a log line and events use it everywhere) {
  CAF_CHECK_EQUAL(json_quote("plain"), "\"plain\"");
  CAF_CHECK_EQUAL(json_quote("a\"b\\c"), "\"a\\\"b\\\\c\"");
  CAF_CHECK_EQUAL(json_quote("x\n{\"node\": 1}"), "\"x\\u000a{\\\"node\\\": 1}\"");
  CAF_CHECK_EQUAL(json_quote(std::string("\x01\x7f", 2)), "\"\\u0001\\u007f\"");
  CAF_CHECK_EQUAL(json_quote("caf\xc3\xa9 \xe2\x82\xac"), "\"caf\xc3\xa9 \xe2\x82\xac\"");  // UTF-8 kept
  CAF_CHECK_EQUAL(json_quote("\xff\xc3"), "\"\\ufffd\\ufffd\"");  // not UTF-8
  CAF_CHECK_EQUAL(json_quote("\xed\xa0\x80"), "\"\\ufffd\\ufffd\\ufffd\"");  // a surrogate
  CAF_CHECK_EQUAL(nodes_value({NodeInfo{"n\"}, {\"x", 2, 1.5}}).dump(),
                  "[{\"name\": \"n\\\"}, {\\\"x\", \"cores\": 2, \"perf\": 1.500}]");
  // Scope, kind and fields, keys and nested values: every string goes through json_quote.
  Event e(Ev::node_lost, "w\"1");
  e.scope = {{"node", "m\n"}, {"session", 7u}};
  e.with("reason", "x\"}, {\"forged\": 1").with("frame", Json::number(1.23456, 2)).with("ok", false);
  e.with("list", Json::array({Json(1), Json("a\\b"), Json::number(std::nan(""))}));
  CAF_CHECK_EQUAL(to_json_line(e), "{\"node\": \"m\\u000a\", \"session\": 7, \"node_lost\": \"w\\\"1\", "
                                   "\"reason\": \"x\\\"}, {\\\"forged\\\": 1\", \"frame\": 1.23, \"ok\": false, "
                                   "\"list\": [1, \"a\\\\b\", null]}");
  CAF_CHECK(*e.field("node") == Json("m\n"));
  CAF_CHECK(e.field("missing") == nullptr);
}

// The checks a parent applies to what its children send.
CAF_TEST(check_tile and check_nodes reject impossible tiles and node lists) {
  const PacketLayout pl{2, 2};
  const Rect task{4, 2, 10, 8};
  TileResult ok;
  ok.frame = 7;
  ok.pixels = task;
  ok.rgba.assign(size_t(task.area()) * 4, 0);
  CostMap cm;
  cm.packets = {2, 1, 5, 4};
  cm.cost.assign(size_t(cm.packets.area()), 10);
  Sat::from_cost_map(cm).serialize_into(ok.sat);
  CAF_CHECK_EQUAL(check_tile(ok, 7, task, pl, kSize, kSize), "");
  auto bad = [&](auto mutate) {
    TileResult t = ok;
    mutate(t);
    return !check_tile(t, 7, task, pl, kSize, kSize).empty();
  };
  CAF_CHECK(bad([](TileResult& t) { t.frame = 6; }));
  CAF_CHECK(bad([](TileResult& t) { t.pixels = {4, 2, 10, 9}; }));
  CAF_CHECK(bad([](TileResult& t) { t.rgba.pop_back(); }));
  CAF_CHECK(bad([](TileResult& t) { t.kernel_ms = std::nan(""); }));
  CAF_CHECK(bad([](TileResult& t) { t.rendering_ms = -1; }));
  CAF_CHECK(bad([](TileResult& t) { t.sat.resize(t.sat.size() - 8); }));
  CAF_CHECK(bad([](TileResult& t) {
    CostMap other;
    other.packets = {0, 0, 3, 3};
    other.cost.assign(9, 1);
    Sat::from_cost_map(other).serialize_into(t.sat);  // a SAT of other packets
  }));
  // A tile that stopped early carries its figures and nothing else.
  TileResult stopped;
  stopped.frame = 7;
  stopped.pixels = task;
  stopped.cancelled = true;
  CAF_CHECK_EQUAL(check_tile(stopped, 7, task, pl, kSize, kSize, true, kAllGuides), "");
  TileResult stopped_with_pixels = ok;
  stopped_with_pixels.cancelled = true;
  CAF_CHECK_NOT_EQUAL(check_tile(stopped_with_pixels, 7, task, pl, kSize, kSize), "");
  stopped.rendering_ms = -1;
  CAF_CHECK_NOT_EQUAL(check_tile(stopped, 7, task, pl, kSize, kSize), "");
  // Depths for the balancer's reprojection: none, or 4 bytes for each of the task's packets.
  TileResult deep = ok;
  deep.depth.assign(size_t(cm.packets.area()) * 4, 0xff);  // any float (here NaN) is taken
  CAF_CHECK_EQUAL(check_tile(deep, 7, task, pl, kSize, kSize), "");
  CAF_CHECK(bad([&](TileResult& t) { t.depth.assign(size_t(cm.packets.area()) * 4 - 1, 0); }));
  CAF_CHECK(bad([&](TileResult& t) { t.depth.assign(size_t(cm.packets.area()) * 4 + 4, 0); }));
  // A progressive still's tiles carry their radiance: 12 bytes a pixel, finite, not negative.
  CAF_CHECK(!check_tile(ok, 7, task, pl, kSize, kSize, true).empty());  // asked for and missing
  TileResult lit = ok;
  lit.radiance.assign(size_t(task.area()) * 12, 0);
  CAF_CHECK_EQUAL(check_tile(lit, 7, task, pl, kSize, kSize, true), "");
  CAF_CHECK(!check_tile(lit, 7, task, pl, kSize, kSize, false).empty());  // not asked for
  auto bad_radiance = [&](float v) {
    TileResult t = lit;
    std::memcpy(t.radiance.data() + 12 * 5 + 4, &v, 4);
    return !check_tile(t, 7, task, pl, kSize, kSize, true).empty();
  };
  CAF_CHECK(!bad_radiance(0.25f));
  CAF_CHECK(bad_radiance(std::nanf("")));
  CAF_CHECK(bad_radiance(-1.0f));
  CAF_CHECK(bad_radiance(std::numeric_limits<float>::infinity()));
  lit.radiance.pop_back();
  CAF_CHECK(!check_tile(lit, 7, task, pl, kSize, kSize, true).empty());
  lit.radiance.assign(size_t(task.area()) * 12, 0);
  // A denoised still's tiles carry its guides: all 8 floats a pixel (sample 0) or the open
  // fraction alone, each in its range; missing, unasked or out of range is an impossible tile.
  TileResult guided = lit;
  std::vector<float> g(size_t(task.area()) * kGuideFloats, 0.0f);
  for (size_t p = 0; p < size_t(task.area()); ++p) g[p * kGuideFloats + 2] = 1, g[p * kGuideFloats + 3] = 2, g[p * kGuideFloats + 7] = 0.5f;
  guided.guides.resize(g.size() * 4);
  std::memcpy(guided.guides.data(), g.data(), guided.guides.size());
  CAF_CHECK_EQUAL(check_tile(guided, 7, task, pl, kSize, kSize, true, kAllGuides), "");
  CAF_CHECK(!check_tile(guided, 7, task, pl, kSize, kSize, true, kOpenGuides).empty());  // the wrong size
  CAF_CHECK(!check_tile(guided, 7, task, pl, kSize, kSize, true).empty());               // not asked for
  CAF_CHECK(!check_tile(lit, 7, task, pl, kSize, kSize, true, kAllGuides).empty());     // asked for and missing
  auto bad_guide = [&](size_t at, float v) {
    TileResult t = guided;
    std::memcpy(t.guides.data() + (5 * kGuideFloats + at) * 4, &v, 4);
    return !check_tile(t, 7, task, pl, kSize, kSize, true, kAllGuides).empty();
  };
  CAF_CHECK(!bad_guide(3, -1.0f));  // a miss
  CAF_CHECK(bad_guide(0, std::nanf("")));
  CAF_CHECK(bad_guide(3, -0.5f));
  CAF_CHECK(bad_guide(4, -1.0f));
  CAF_CHECK(bad_guide(7, 1.5f));
  CAF_CHECK(bad_guide(6, std::numeric_limits<float>::infinity()));
  TileResult open = lit;
  open.guides.assign(size_t(task.area()) * 4, 0);
  CAF_CHECK_EQUAL(check_tile(open, 7, task, pl, kSize, kSize, true, kOpenGuides), "");
  const float over = 2.0f;
  std::memcpy(open.guides.data() + 8, &over, 4);
  CAF_CHECK(!check_tile(open, 7, task, pl, kSize, kSize, true, kOpenGuides).empty());
  // Radiance is asked of the ray tracer only.
  RenderBatch b;
  b.width = b.height = 16;
  b.tasks = {Rect{0, 0, 16, 16}};
  b.radiance = true;
  CAF_CHECK_EQUAL(check_batch(b, Limits{}), "");
  b.guides = kAllGuides;
  CAF_CHECK_EQUAL(check_batch(b, Limits{}), "");
  b.guides = 3;  // no such kind
  CAF_CHECK(!check_batch(b, Limits{}).empty());
  b.guides = kOpenGuides;
  b.radiance = false;  // guides serve a refining still
  CAF_CHECK(!check_batch(b, Limits{}).empty());
  b.guides = kNoGuides;
  b.radiance = true;
  b.renderer = uint8_t(RendererKind::rasterizer);
  CAF_CHECK(!check_batch(b, Limits{}).empty());
  CAF_CHECK_EQUAL(check_nodes({NodeInfo{"a:1", 4, 1.5}}), "");
  CAF_CHECK(!check_nodes({NodeInfo{"a:1", 0, 1}}).empty());
  CAF_CHECK(!check_nodes({NodeInfo{"a:1", 1, std::nan("")}}).empty());
  CAF_CHECK(!check_nodes({NodeInfo{"a:1", 1, 0}}).empty());
  CAF_CHECK(!check_nodes({NodeInfo{"", 1, 1}}).empty());
  CAF_CHECK(!check_nodes({NodeInfo{"a\"b", 1, 1}}).empty());
}

// What a worker does with forwarded scene records it cannot decode or apply.
CAF_TEST(apply_records reports broken forwarded updates) {
  Scene scene;
  CAF_CHECK_EQUAL(apply_records(scene, encode(tiny_scene()), Limits{}), "");
  CAF_CHECK_EQUAL(scene.meshes().size(), 1u);
  CAF_CHECK(!apply_records(scene, std::vector<uint8_t>{'T', 'S', protocol::kVersion, 0, 5, 0, 0, 0, 1}, Limits{}).empty());
  SetMesh bad;
  bad.id = 30;
  bad.mesh.positions = 2;  // the u32 index buffer as positions
  CAF_CHECK(!apply_records(scene, encode(std::vector<ClientRecord>{bad}), Limits{}).empty());
}
