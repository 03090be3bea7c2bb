// Workers live exactly as long as their session, and the cluster port is bounded and checked,
// with real `tessera serve` processes on localhost (the built binary, TESSERA_BINARY):
//  - 50 sessions through a master leave the worker process at its baseline RSS and thread
//    count, with no live worker;
//  - a master that is stopped (SIGSTOP: connected but silent) or killed (SIGKILL) takes its
//    workers with it, within stated bounds;
//  - a hostile peer that talks to the cluster port directly (CAF remote_actor, as any peer
//    could) gets its malformed opens refused, every tile of a bad batch failed, and no more
//    than max-workers workers; the node serves on.
#include <catch2/catch.hpp>

#include <signal.h>

#include <chrono>
#include <fstream>
#include <memory>
#include <string>
#include <vector>

#include <caf/all.hpp>
#include <caf/io/all.hpp>

#include "protocol/scene_records.h"
#include "tests/cluster/cluster_checks.h"
#include "tests/e2e/node_fixture.h"
#include "tests/cluster/serve_node.h"
#include "tests/e2e/process.h"

using namespace tessera;
using namespace tessera::test;
using protocol::DisplayKind;

namespace {

constexpr int W = 96, H = 64;

// ASan keeps freed memory in its quarantine (256 MB by default) and its own shadow, so RSS says
// nothing about our leaks there; threads still do (and LeakSanitizer checks the heap).
#if defined(__SANITIZE_ADDRESS__)
constexpr bool kAsan = true;
#elif defined(__has_feature)
#if __has_feature(address_sanitizer)
constexpr bool kAsan = true;
#else
constexpr bool kAsan = false;
#endif
#else
constexpr bool kAsan = false;
#endif
using clock_type = std::chrono::steady_clock;

// A node of this test: keep-alives every 200 ms (reconnect-ms); a worker ends after 5 silent
// periods (1 s).
struct Node : ServeNode {
  explicit Node(std::vector<std::string> extra) : ServeNode(with_keepalive(std::move(extra))) {}
  static std::vector<std::string> with_keepalive(std::vector<std::string> extra) {
    extra.insert(extra.begin(), "--tessera.keepalive-misses=5");
    return extra;
  }
  // The live-worker count of the node's last worker_opened / worker_closed line (-1: none yet).
  long live_workers() {
    const std::string& e = p->err();
    auto at = e.rfind("\"live_workers\": ");
    return at == std::string::npos ? -1 : std::stol(e.substr(at + 16));
  }
};

Node worker(const std::string& name, std::vector<std::string> extra = {}) {
  std::vector<std::string> a{"--no-http", "--cluster-port", "0", "--tessera.name=" + name};
  a.insert(a.end(), extra.begin(), extra.end());
  return Node(a);
}

// VmRSS (kB) or Threads of a process, from /proc/PID/status.
long proc_status(pid_t pid, const std::string& key) {
  std::ifstream f("/proc/" + std::to_string(pid) + "/status");
  std::string line;
  while (std::getline(f, line))
    if (line.rfind(key + ":", 0) == 0) return std::stol(line.substr(key.size() + 1));
  return -1;
}

// A client session through the master: handshake, the pavilion, one frame, close.
void one_session(uint16_t port, uint32_t frame) {
  ProtoClient c;
  REQUIRE(c.connect(port));
  REQUIRE(c.handshake(DisplayKind::jpeg, W, H, 80));
  REQUIRE(c.upload(pavilion().scene));
  auto f = c.render(pavilion_loop().camera(frame % 200), frame);
  REQUIRE(f);
  CHECK(f->frame == frame);
}

double seconds_since(clock_type::time_point t0) {
  return std::chrono::duration<double>(clock_type::now() - t0).count();
}

}  // namespace

TEST_CASE("50 sessions through a master leave its worker at the baseline: no live worker, RSS and threads back",
          "[cluster][fault]") {
  Node w = worker("w");
  Node m({"--port", "0", "--no-render", "--children", w.addr()});  // the worker renders everything
  REQUIRE(wait_for([&] { return m.p->err_count("\"child_connected\"") == 1; }, 20000));
  const pid_t pid = w.p->pid();
  const long threads_before = proc_status(pid, "Threads");

  // The first session loads what stays loaded (Embree, TBB, CAF's BASP buffers, the heap it
  // grew): the baseline is taken after it.
  one_session(m.http, 1);
  REQUIRE(wait_for([&] { return w.live_workers() == 0; }, 10000));
  REQUIRE(wait_for([&] { return proc_status(pid, "Threads") <= threads_before; }, 5000));
  REQUIRE(wait_for([&] { return w.p->err_count("\"heap_trimmed\"") == 1; }, 5000));
  const long rss0 = proc_status(pid, "VmRSS"), threads0 = proc_status(pid, "Threads");

  const auto t0 = clock_type::now();
  for (uint32_t s = 2; s <= 50; ++s) one_session(m.http, s);
  const double churn_s = seconds_since(t0);
  INFO("worker stderr tail: " << w.p->err().substr(w.p->err().size() > 3000 ? w.p->err().size() - 3000 : 0));
  // One worker per session. On a loaded machine (or under ASan) the master may give up on one:
  // an open that timed out (3 s) is retried, and the first worker then ends with its session
  // too (or as an orphan); a batch or node-list query that timed out makes the master drop the
  // worker ("node_lost") and open another at its next reconnect, and it ends the dropped one
  // itself at its next commit (an exit, which the worker does not log as "ended") unless the
  // session ends first ("parent down").
  const size_t opened = w.p->err_count("\"worker_opened\"");
  const size_t given_up = m.p->err_count("\"join_failed\"") + m.p->err_count("\"node_lost\"");
  INFO("master's failed joins: " << m.p->err_count("\"join_failed\"") << ", lost nodes: " << m.p->err_count("\"node_lost\"")
                                  << ", recovered frames: " << m.p->err_count("\"recovering\""));
  CHECK(opened >= 50);
  CHECK(opened <= 50 + given_up);
  // Every worker ends with its session (the log's count of live workers comes back to 0).
  CHECK(wait_for([&] { return w.p->err_count("\"worker_closed\"") == opened && w.live_workers() == 0; }, 10000));
  const size_t ended = w.p->err_count("\"ended\": \"parent down\"") + w.p->err_count("\"orphaned\"");
  CHECK(ended <= opened);
  CHECK(ended + m.p->err_count("\"node_lost\"") >= opened);
  // The node hands freed heap back to the OS a tick or two after its last worker ended
  // ("heap_trimmed"); measure after that.
  CHECK(wait_for(
      [&] {
        const std::string& e = w.p->err();
        auto trimmed = e.rfind("\"heap_trimmed\""), closed = e.rfind("\"worker_closed\"");
        return trimmed != std::string::npos && trimmed > closed;
      },
      5000));
  // Threads: exactly the baseline (each worker's renderer thread ends with it; before the fix
  // every session left one). RSS: within 48 MiB of the baseline, less than what one leaked
  // worker holds (the pavilion, its BVH and its renderer: ~60 MB per session before the fix).
  // It does not come back to the byte: the heap keeps live small blocks scattered over pages
  // (21..32 MB over the baseline in three runs here, with up to 2 sessions overlapping).
  // A heap trim scheduled by a worker that ended while others lived runs on a thread of its own
  // for up to a second (actors/node.h, schedule_heap_trim): allow that long for it to end.
  long rss = 0, threads = 0;
  const bool back = wait_for(
      [&] {
        rss = proc_status(pid, "VmRSS");
        threads = proc_status(pid, "Threads");
        return threads <= threads0 && (kAsan || rss <= rss0 + 48 * 1024);
      },
      3000);
  INFO("baseline RSS " << rss0 << " kB, " << threads0 << " threads; after 50 sessions " << rss << " kB, " << threads
                       << " threads (" << churn_s << " s for 49 sessions)");
  CHECK(back);
  WARN("worker baseline RSS " << rss0 << " kB / " << threads0 << " threads; after 50 sessions " << rss << " kB / "
                              << threads << " threads; 49 sessions in " << churn_s << " s");
}

TEST_CASE("A master that stops answering or is killed takes its workers with it", "[cluster][fault]") {
  Node w = worker("w");

  // Stopped (SIGSTOP): the connection stays open, the keep-alives stop. The worker ends after
  // 5 silent periods of 200 ms, checked every 200 ms: 1.0..1.4 s (bound: 3 s).
  {
    Node m({"--port", "0", "--children", w.addr()});
    REQUIRE(wait_for([&] { return m.p->err_count("\"child_connected\"") == 1; }, 20000));
    ProtoClient c;
    REQUIRE(c.connect(m.http));
    REQUIRE(c.handshake(DisplayKind::jpeg, W, H, 80));
    REQUIRE(c.upload(pavilion().scene));
    REQUIRE(c.render(pavilion_loop().camera(0), 1));
    REQUIRE(w.live_workers() == 1);
    // An idle session keeps its worker: keep-alives arrive although nothing else does.
    std::this_thread::sleep_for(std::chrono::milliseconds(1500));
    CHECK(w.live_workers() == 1);
    REQUIRE(c.render(pavilion_loop().camera(10), 2));
    m.p->signal(SIGSTOP);
    const auto t0 = clock_type::now();
    CHECK(wait_for([&] { return w.live_workers() == 0; }, 3000));
    const double ended_s = seconds_since(t0);
    INFO("worker stderr: " << w.p->err());
    CHECK(w.p->err_count("\"ended\": \"parent silent\"") == 1);
    CHECK(ended_s >= 0.9);  // not before the parent had missed its 5 periods
    WARN("stopped master: its worker ended after " << ended_s << " s");
    m.p->signal(SIGKILL);
    m.p->signal(SIGCONT);
  }

  // Killed (SIGKILL): the connection closes and the worker ends at once ("parent down"), or by
  // the silence rule (1.0..1.4 s, "parent silent") when the close comes later. It can: the
  // kernel frees a killed process's memory before it closes its sockets (do_exit: exit_mm, then
  // exit_files), and on a loaded 2-core machine the link's end also waits for the worker's
  // middleman thread. Bound: the silence rule's, 3 s, as above (CI once saw one worker end
  // silent at 1.02 s and the other not yet at 1.0 s).
  {
    Node m({"--port", "0", "--children", w.addr()});
    REQUIRE(wait_for([&] { return m.p->err_count("\"child_connected\"") == 1; }, 20000));
    ProtoClient a, b;
    for (ProtoClient* c : {&a, &b}) {
      REQUIRE(c->connect(m.http));
      REQUIRE(c->handshake(DisplayKind::jpeg, W, H, 80));
      REQUIRE(c->upload(pavilion().scene));
      REQUIRE(c->render(pavilion_loop().camera(0), 1));
    }
    REQUIRE(w.live_workers() == 2);
    const size_t silent_before = w.p->err_count("\"ended\": \"parent silent\"");
    m.p->signal(SIGKILL);
    const auto t0 = clock_type::now();
    CHECK(wait_for([&] { return w.live_workers() == 0; }, 3000));
    const double ended_s = seconds_since(t0);
    INFO("worker stderr: " << w.p->err());
    // Either way both end, within the bound, each with one of the two reasons.
    CHECK(w.p->err_count("\"ended\": \"parent down\"") + w.p->err_count("\"ended\": \"parent silent\"") ==
          2 + silent_before);
    WARN("killed master: its 2 workers ended after " << ended_s << " s");
  }
  CHECK(w.p->wait(0) == std::nullopt);  // the worker process itself runs on
}

TEST_CASE("A hostile peer on the cluster port gets refusals and failed tiles; the node serves on", "[cluster][fault]") {
  Node w = worker("w", {"--tessera.max-workers=3", "--tessera.max-width=640", "--tessera.max-height=480"});
  PeerConfig cfg;
  caf::actor_system sys{cfg};
  auto node = sys.middleman().remote_actor<node_actor>("127.0.0.1", w.cluster);
  REQUIRE(node);
  {
    caf::scoped_actor self{sys};
    auto open = [&](OpenRequest req, std::string* error) {
      subtree_actor out;
      self->request(*node, std::chrono::seconds(10), open_atom::value, req)
          .receive([&](OpenReply& r) { out = caf::actor_cast<subtree_actor>(r.worker); },
                   [&](caf::error& e) { *error = sys.render(e); });
      return out;
    };
    OpenRequest good{77, "peer", 2, 2};
    good.timeout_ms = 5000;
    good.keepalive_ms = 10000;  // 50 s of silence allowed: the test ends before that

    // Malformed opens are refused with the reason.
    auto refused = [&](auto mutate, const std::string& why) {
      OpenRequest r = good;
      mutate(r);
      std::string err;
      CHECK(!open(r, &err));
      INFO("error: " << err);
      CHECK(err.find("open refused: " + why) != std::string::npos);
    };
    refused([](OpenRequest& r) { r.master = "x\"}\n{\"node\": \"forged"; }, "a master name");
    refused([](OpenRequest& r) { r.packet_w = 1000; }, "packet layout 1000x2");
    refused([](OpenRequest& r) { r.keepalive_ms = 0; }, "keep-alive period of 0 ms");
    // The refusals' lines come through the node's logger and the test's stderr reader, maybe
    // after the replies (seen under ASan on a busy machine: 2 == 3), as with worker_opened below.
    CHECK(wait_for([&] { return w.p->err_count("\"open_refused\"") == 3; }, 5000));
    CHECK(w.p->err_count("forged") == 0);

    // A worker, with a scene, and batches that no client could send through this node.
    std::string err;
    subtree_actor wk = open(good, &err);
    REQUIRE(wk);
    self->send(wk, update_atom::value, Payload{protocol::encode(protocol::scene_to_records(pavilion().scene))}, true);
    auto batch = [] {
      RenderBatch b;
      b.frame = 1;
      b.width = W;
      b.height = H;
      b.ao_samples = 1;
      b.max_depth = 2;
      b.timeout_ms = 5000;
      b.tasks = {Rect{0, 0, W, H}};
      return b;
    };
    auto render = [&](const RenderBatch& b) {
      BatchReply out;
      self->request(wk, std::chrono::seconds(20), render_atom::value, b)
          .receive([&](BatchReply& r) { out = std::move(r); }, [&](caf::error& e) { FAIL(sys.render(e)); });
      return out;
    };
    std::vector<std::pair<std::string, std::function<void(RenderBatch&)>>> bad = {
        {"frame 100000x64", [](RenderBatch& b) { b.width = 100000; }},
        {"ao_samples 100000", [](RenderBatch& b) { b.ao_samples = 100000; }},
        {"max_depth 100000", [](RenderBatch& b) { b.max_depth = 100000; }},
        {"renderer kind 9", [](RenderBatch& b) { b.renderer = 9; }},
        {"outside the frame", [](RenderBatch& b) { b.tasks = {Rect{0, 0, W, H + 1}}; }},
        {"batch of 2 tasks for a sub-tree of 1 nodes", [](RenderBatch& b) { b.tasks.push_back(Rect{0, 0, 1, 1}); }},
    };
    const auto t0 = clock_type::now();
    for (auto& [why, mutate] : bad) {
      RenderBatch b = batch();
      mutate(b);
      BatchReply r = render(b);
      INFO("batch: " << why);
      REQUIRE(r.tiles.size() == b.tasks.size());
      for (auto& t : r.tiles) {
        CHECK(t.error.find(why) != std::string::npos);
        CHECK(t.rgba.empty());
      }
    }
    CHECK(seconds_since(t0) < 2.0);  // refused, not rendered
    BatchReply ok = render(batch());
    REQUIRE(ok.tiles.size() == 1);
    CHECK(ok.tiles[0].error == "");
    CHECK(ok.tiles[0].rgba.size() == size_t(W * H * 4));
    CHECK(wait_for([&] { return w.p->err_count("\"bad_batch\"") == 5; }, 5000));

    // max-workers=3: two more opens are served, the next is refused.
    CHECK(open(good, &err));
    CHECK(open(good, &err));
    // The node logs worker_opened through its logger actor, and the test reads its stderr on a
    // thread of its own: the line can come after the open's reply (seen under ASan on a busy
    // machine: 2 == 3).
    CHECK(wait_for([&] { return w.live_workers() == 3; }, 5000));
    err.clear();
    CHECK(!open(good, &err));
    INFO("error: " << err);
    CHECK(err.find("has 3 live workers, its max-workers") != std::string::npos);
    CHECK(w.p->wait(0) == std::nullopt);  // still running
  }
  // The peer's actor is gone: its workers go too.
  CHECK(wait_for([&] { return w.live_workers() == 0; }, 5000));
  CHECK(wait_for([&] { return w.p->err_count("\"worker_closed\"") == 3; }, 5000));
}

TEST_CASE("Bad worker-bound settings end serve with a clear error", "[cluster]") {
  auto refused = [](const std::string& arg, const std::string& message) {
    Process p({TESSERA_BINARY, "serve", "--port", "0", arg});
    auto status = p.wait(20000);
    INFO("arg: " << arg << "; stderr: " << p.err());
    REQUIRE(status);
    CHECK(WIFEXITED(*status));
    CHECK(WEXITSTATUS(*status) != 0);
    CHECK(p.err().find(message) != std::string::npos);
  };
  refused("--tessera.max-workers=-1", "max-workers must be in 0..100000");
  refused("--tessera.keepalive-misses=1", "keepalive-misses must be in 2..1000");
  refused("--tessera.reconnect-ms=70000", "reconnect-ms must be in 10..60000");
  // The admission settings (net/admission.h) are checked the same way.
  refused("--tessera.max-connections-per-ip=-1", "max-connections-per-ip must be >= 0");
  refused("--tessera.allowed-origins=[\"ftp://x/y\"]", "is not \"self\", \"loopback\", \"*\" or an origin");
  refused("--tessera.token-key=/nonexistent/tessera.key", "token-key");
}
