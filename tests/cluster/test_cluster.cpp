// A real tree of `tessera serve` processes on localhost (the built binary, TESSERA_BINARY):
// workers publish their node on a cluster port, a master names them as children, and a
// protocol client streams the pavilion through the master. Frames must match the ray
// tracer's direct render while nodes are killed (SIGKILL, mid-stream) and come back.
#include <catch2/catch.hpp>

#include <signal.h>

#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "tests/cluster/cluster_checks.h"
#include "tests/e2e/node_fixture.h"
#include "tests/cluster/serve_node.h"
#include "tests/e2e/process.h"

using namespace tessera;
using namespace tessera::test;
using protocol::DisplayKind;

namespace {

constexpr int W = 240, H = 136;

using Node = ServeNode;

Node worker(const std::string& name, uint16_t port = 0) {
  return Node({"--no-http", "--cluster-port", std::to_string(port), "--tessera.name=" + name});
}


}  // namespace

TEST_CASE("Two worker processes render for a master; a killed worker's tiles are re-rendered and it rejoins",
          "[cluster][fault]") {
  Node w1 = worker("w1"), w2 = worker("w2");
  const uint16_t p1 = w1.cluster;
  // Without the per-frame lines: every other event still shows (the recovering ones below).
  Node m({"--port", "0", "--no-render", "--tessera.log-frames=false", "--children", w1.addr() + "," + w2.addr()});
  REQUIRE(wait_for([&] { return m.p->err_count("\"child_connected\"") == 2; }, 20000));

  ProtoClient c;
  REQUIRE(c.connect(m.http));
  auto hs = c.handshake(DisplayKind::jpeg, W, H, 95);
  REQUIRE(hs);
  CHECK(hs->nodes == 2);  // a dedicated master: both workers render, the master does not
  REQUIRE(c.upload(pavilion().scene));
  uint32_t n = 1;
  for (size_t k : {0, 40, 80, 81}) check_frame(c, k, n++, *m.p);
  CHECK(m.p->err_count("\"cluster_frame\"") >= 4);  // per-node figures of every frame
  // The workers return their packets' depths, and the master tiles frame 81 from frame 80's
  // cost carried into its camera (frames 40 and 80 may be cuts: the loop moved far).
  CHECK(m.p->err_count("\"predictor\": \"area\"") >= 1);  // the first frame
  CHECK(m.p->err_count("\"predictor\": \"reprojected\"") >= 1);
  CHECK(m.p->err_count("\"predictor\": \"previous_frame\"") == 0);
  CHECK(w1.p->err_count("\"worker_opened\"") == 1);

  // A worker dies mid-stream: every frame still arrives and is right.
  w1.p->signal(SIGKILL);
  for (size_t k : {100, 120, 140}) check_frame(c, k, n++, *m.p);
  CHECK(m.p->err_count("\"node_lost\"") >= 1);
  CHECK(m.p->err_count("\"recovering\"") >= 1);  // hidden with the frame lines before events had kinds
  CHECK(m.p->err_count("\"sent_ms\"") == 0);      // no frame event

  // It comes back on the same port: the session reopens a worker there, sends it the scene,
  // and tiles over both workers again.
  Node back = worker("w1b", p1);
  bool rejoined = wait_for([&] { return m.p->err_count("\"joined\": \"127.0.0.1:" + std::to_string(p1)) == 2; }, 20000);
  INFO("master stderr: " << m.p->err());
  REQUIRE(rejoined);
  for (size_t k : {160, 180}) check_frame(c, k, n++, *m.p);
  CHECK(m.p->err_count("\"name\": \"w1b\"") >= 1);
  CHECK(back.p->err_count("\"worker_opened\"") == 1);
  CHECK(m.p->err_count("\"error\"") == 0);  // the client never got an error
}

TEST_CASE("Within a frame budget a tree renders small interactive frames and refines the still at full size",
          "[cluster][budget]") {
  // The resolution changes between the interactive frames and the still go down the tree as
  // records; the tiles of both workers are averaged by the master.
  Node w1 = worker("w1"), w2 = worker("w2");
  Node m({"--port", "0", "--no-render", "--tessera.frame-budget-ms=1", "--children", w1.addr() + "," + w2.addr()});
  REQUIRE(wait_for([&] { return m.p->err_count("\"child_connected\"") == 2; }, 20000));
  ProtoClient c;
  REQUIRE(c.connect(m.http));
  auto hs = c.handshake(DisplayKind::jpeg, W, H, 95);
  REQUIRE(hs);
  REQUIRE(hs->nodes == 2);
  REQUIRE(c.upload(pavilion().scene));
  REQUIRE(c.send({protocol::Refine{4}}));
  INFO("master stderr tail: " << m.p->err().substr(m.p->err().size() > 3000 ? m.p->err().size() - 3000 : 0));
  auto first = c.render(pavilion_loop().camera(0), 1, 90000);  // the workers build the scene first
  REQUIRE(first);
  CHECK(first->width == W);
  // Frame 1 refines to 4 samples at full size (nothing was measured before it).
  uint16_t samples = first->samples;
  while (samples < 4) {
    auto f = c.next<protocol::Frame>();
    REQUIRE(f);
    REQUIRE(f->frame == 1);
    samples = f->samples;
  }
  for (uint32_t n = 2; n <= 3; ++n) {
    auto small = c.render(pavilion_loop().camera(20 * n), n);
    REQUIRE(small);
    CHECK(small->width == W / 4);
    CHECK(small->height == H / 4);
    uint16_t got = 0;
    protocol::Frame last;
    while (got < 4) {
      auto f = c.next<protocol::Frame>();
      REQUIRE(f);
      REQUIRE(f->frame == n);
      CHECK(f->refined);
      CHECK(f->width == W);
      got = f->samples;
      last = std::move(*f);
    }
    // The still is the camera's image: the refined average is close to a direct render.
    const double psnr =
        compare(decode_jpeg(last.payload), render_direct(pavilion().scene, pavilion_loop().camera(20 * n), W, H, 0, 0)).psnr;
    INFO("frame " << n << " PSNR " << psnr);
    CHECK(psnr >= 28.0);
  }
  CHECK(m.p->err_count("\"error\"") == 0);
  CHECK(m.p->err_count("\"node_lost\"") == 0);
}

TEST_CASE("A render request during a still's sample stops the workers' tasks of that sample", "[cluster][refine]") {
  // 320x180 with 8 AO rays, half a frame per worker on one thread each: a sample takes far
  // longer than the step to the next one, so a request sent when a refined frame arrives lands
  // inside a sample (tried up to 5 times), and well under the task timeout in a sanitizer
  // build. Both workers get the master's cancel and stop.
  Node w1 = worker("w1"), w2 = worker("w2");
  Node m({"--port", "0", "--no-render", "--tessera.log-frames=false", "--children", w1.addr() + "," + w2.addr()});
  REQUIRE(wait_for([&] { return m.p->err_count("\"child_connected\"") == 2; }, 20000));
  ProtoClient c;
  REQUIRE(c.connect(m.http));
  auto hs = c.handshake(DisplayKind::jpeg, 320, 180, 80);
  REQUIRE(hs);
  REQUIRE(hs->nodes == 2);
  REQUIRE(c.upload(pavilion().scene));
  REQUIRE(c.send({protocol::Settings{8, 4}, protocol::Refine{256}}));
  uint32_t frame = 1;
  REQUIRE(c.render(pavilion_loop().camera(0), frame, 90000));  // the workers build the scene first
  bool both = false;
  for (int attempt = 0; attempt < 5 && !both; ++attempt) {
    auto refined = c.next<protocol::Frame>();
    REQUIRE(refined);
    REQUIRE(refined->frame == frame);
    ++frame;
    auto f = c.render_past_still(pavilion_loop().camera(frame), frame);
    REQUIRE(f);
    CHECK_FALSE(f->refined);
    both = wait_for([&] { return m.p->err_count("\"tiles_stopped\": 2") >= 1; }, 500);
  }
  INFO("master stderr tail: " << m.p->err().substr(m.p->err().size() > 3000 ? m.p->err().size() - 3000 : 0));
  CHECK(both);
  CHECK(m.p->err_count("stopped early") == 0);  // stopped tiles of an abandoned frame are no node's fault
  CHECK(m.p->err_count("\"node_lost\"") == 0);
  CHECK(m.p->err_count("\"error\"") == 0);
  // The next still refines on both workers as usual.
  auto next = c.next<protocol::Frame>();
  REQUIRE(next);
  CHECK(next->frame == frame);
  CHECK(next->refined);
}

TEST_CASE("A hub relays a sub-tree; when it dies its sub-tree leaves and the rest keeps rendering", "[cluster][fault]") {
  Node w3 = worker("w3"), w4 = worker("w4"), w5 = worker("w5");
  Node hub({"--no-http", "--no-render", "--cluster-port", "0", "--tessera.name=hub", "--children",
            w3.addr() + "," + w4.addr()});
  REQUIRE(wait_for([&] { return hub.p->err_count("\"child_connected\"") == 2; }, 20000));
  Node m({"--port", "0", "--children", hub.addr() + "," + w5.addr()});  // the master renders too
  REQUIRE(wait_for([&] { return m.p->err_count("\"child_connected\"") == 2; }, 20000));

  ProtoClient c;
  REQUIRE(c.connect(m.http));
  auto hs = c.handshake(DisplayKind::jpeg, W, H, 95);
  REQUIRE(hs);
  CHECK(hs->nodes == 4);  // master, w3 and w4 through the hub, w5
  REQUIRE(c.upload(pavilion().scene));
  uint32_t n = 1;
  for (size_t k : {0, 50}) check_frame(c, k, n++, *m.p);
  // Opened by the hub's worker, not by the master (on a loaded machine an open that timed out is
  // retried, so count the opener rather than the opens).
  INFO("w3 stderr: " << w3.p->err());
  CHECK(w3.p->err_count("\"worker_opened\"") >= 1);
  CHECK(w3.p->err_count("\"master\": \"hub\"") == w3.p->err_count("\"worker_opened\""));

  // A page may limit the node count: the strongest nodes first (here all equal: list order).
  ProtoClient limited;
  REQUIRE(limited.connect(m.http));
  protocol::Handshake h2;
  h2.display = DisplayKind::jpeg;
  h2.width = W;
  h2.height = H;
  h2.max_nodes = 2;
  REQUIRE(limited.send({h2}));
  auto hs2 = limited.next<protocol::HandshakeReply>();
  REQUIRE(hs2);
  CHECK(hs2->nodes == 2);

  hub.p->signal(SIGKILL);
  for (size_t k : {100, 150, 200}) check_frame(c, k, n++, *m.p);
  CHECK(m.p->err_count("\"node_lost\": \"" + hub.addr()) >= 1);
  CHECK(m.p->err_count("\"used\": 2") >= 1);  // master and w5 only
  CHECK(m.p->err_count("\"error\"") == 0);
}

TEST_CASE("Bad cluster settings end serve with a clear error", "[cluster]") {
  auto refused = [](std::vector<std::string> extra, const std::string& message) {
    std::vector<std::string> a{TESSERA_BINARY, "serve", "--port", "0"};
    a.insert(a.end(), extra.begin(), extra.end());
    Process p(a);
    auto status = p.wait(20000);
    INFO("args: " << a.back() << "; stderr: " << p.err());
    REQUIRE(status);
    CHECK(WIFEXITED(*status));
    CHECK(WEXITSTATUS(*status) != 0);
    CHECK(p.err().find(message) != std::string::npos);
  };
  refused({"--children", "nonsense"}, "child node 'nonsense' is not host:port");
  refused({"--children", "127.0.0.1:99999"}, "is not host:port");
  refused({"--tessera.task-timeout-ms=10"}, "task-timeout-ms must be >= 50");
  refused({"--tessera.refine-samples=5000"}, "refine-samples must be in 0..4096");
  refused({"--tessera.still-ao-samples=257"}, "still-ao-samples must be in 0..256");
  refused({"--tessera.still-ao-samples=-1"}, "still-ao-samples must be in 0..256");
  refused({"--tessera.frame-budget-ms=-1"}, "frame-budget-ms must be in 0..60000");
  refused({"--tessera.still-delay-ms=10001"}, "still-delay-ms must be in 0..10000");
  refused({"--tessera.adaptive-round=1.5"}, "adaptive-round must be in 0..1");
  refused({"--tessera.adaptive-round=-0.25"}, "adaptive-round must be in 0..1");
  refused({"--cluster-port", "70000"}, "cluster-port must be in -1..65535");
  Node w = worker("taken");
  refused({"--no-http", "--cluster-port", std::to_string(w.cluster)}, "cannot publish the node on 127.0.0.1:");
}
