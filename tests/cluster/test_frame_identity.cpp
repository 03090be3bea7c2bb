// Frames are byte-identical, whatever renders them. On each of the three shared scenes, frames
// along the camera loop (AO on, so the per-frame AO seed is checked too) must carry exactly the
// bytes of the ray tracer's direct render of that camera, encoded the way the node encodes:
//   - one in-process node, JPEG and S3TC displays;
//   - a real tree of `tessera serve` processes (a master that renders and two workers), where
//     the first frame is tiled evenly and later ones by the previous frame's cost maps, so the
//     image is composed from uneven tiles of three processes.
// A refactor of the pipeline that changes a single pixel fails here.
//
// The direct renders are also hashed (FNV-1a 64 of the RGBA) and compared with
// tests/golden/frame-hashes.txt for this machine's ISA and compiler, so the renderer's output
// can be compared exactly across commits on one machine. A machine with no entry gets a
// warning with the lines to add (TESSERA_UPDATE_GOLDEN=1 appends them); other machines round
// floating point differently, so their hashes would differ (test_golden checks the images
// themselves with a tolerance everywhere).
#include <catch2/catch.hpp>

#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <map>
#include <memory>
#include <set>
#include <sstream>
#include <string>
#include <vector>

#include "app/common.h"
#include "codecs/dxt1.h"
#include "codecs/jpeg.h"
#include "renderer/accumulation.h"
#include "renderer/denoise.h"
#include "renderer/sampling.h"
#include "tests/cluster/serve_node.h"
#include "tests/e2e/node_fixture.h"

using namespace tessera;
using namespace tessera::test;
using protocol::DisplayKind;

namespace {

constexpr int W = 256, H = 144, kAo = 2, kDepth = 4, kQuality = 90;
constexpr size_t kFrames = 3;

struct SharedScene {
  std::string name;
  LoadedScene scene;
  CameraLoop loop;
  size_t camera_index(size_t i) const { return i * (loop.frames.size() / kFrames); }
};

const SharedScene& shared_scene(const std::string& name) {
  static std::map<std::string, SharedScene> cache;
  auto it = cache.find(name);
  if (it == cache.end()) {
    const std::string dir = std::string(TESSERA_SCENES_DIR) + "/" + name;
    it = cache.emplace(name, SharedScene{name, load_gltf(dir + "/scene.gltf"), load_camera_loop(dir + "/camera-loop.json")})
             .first;
  }
  return it->second;
}

// A ray tracer synced with the scene seen from camera `k` at W x H.
std::unique_ptr<RayTracer> synced(const SharedScene& s, size_t k, Scene& scene) {
  scene = s.scene.scene;
  scene.set_resolution(W, H);
  scene.set_camera(s.loop.camera(k));
  auto rt = std::make_unique<RayTracer>();
  std::vector<std::string> warnings;
  rt->sync(scene, warnings);
  return rt;
}

// The direct render of camera `k` as a session renders its frame `seq`.
Image direct(const SharedScene& s, size_t k, uint32_t seq) {
  Scene scene;
  auto rt = synced(s, k, scene);
  RenderSettings settings;
  settings.ao_samples = kAo;
  settings.max_depth = kDepth;
  settings.frame = seq;
  TaskResult r;
  rt->render({0, 0, W, H}, settings, r);
  return std::move(r.image);
}

// The progressive still of camera `k` as a session refines it: samples 0..n-1 seeded by the
// still's first frame `seed` (sample 0 with the session's AO rays, the later ones with the
// node's still-ao-samples), averaged as radiance (renderer/accumulation.h), and denoised as
// the node denoises it (AO under a sky, the node's default threshold; frame_actor.cpp).
Image direct_refined(const SharedScene& s, size_t k, uint32_t seed, uint32_t n) {
  Scene scene;
  auto rt = synced(s, k, scene);
  Accumulation acc;
  acc.reset(W, H, scene.environment().linear);
  bool denoising = kAo > 0 && max_component(scene.environment().ambient) > 0;
  StillAo ao;
  std::vector<float> guides;
  uint32_t shown = 0;
  Image out;
  for (uint32_t i = 0; i < n; ++i) {
    RenderSettings settings;
    settings.ao_samples = i == 0 ? kAo : sampling::kStillAoSamples;
    settings.max_depth = kDepth;
    settings.frame = seed;
    settings.sample = i;
    settings.radiance = true;
    settings.guides = denoising;
    TaskResult r;
    rt->render({0, 0, W, H}, settings, r);
    acc.add(r.radiance, W, H, 0, 0);
    acc.end_sample();
    out = {};
    if (denoising) {
      if (i == 0) {
        ao.reset(W, H);
        guides = r.guides;
      }
      ao.add(r.guides);  // only the open fractions count after sample 0
      if (i > 0 && shown_while_denoising(i + 1, shown, n)) {
        shown = i + 1;
        DenoisedStep step = denoise_step(acc, guides, ao, kDenoiseBelowDb);
        denoising = step.denoised;
        if (denoising) out = std::move(step.image);
      }
    }
  }
  return out.rgba.empty() ? acc.average() : out;
}

std::vector<uint8_t> encoded(const Image& img, DisplayKind display) {
  std::vector<uint8_t> out;
  if (display == DisplayKind::s3tc) {
    dxt1_encode(img, Dxt1Fit::range, out);  // what the encoder actor uses
  } else {
    JpegEncoder enc;
    std::string err;
    REQUIRE(enc.encode(img, kQuality, out, err));
  }
  return out;
}

uint64_t fnv1a(const std::vector<uint8_t>& bytes) {
  uint64_t h = 1469598103934665603ull;
  for (uint8_t b : bytes) h = (h ^ b) * 1099511628211ull;
  return h;
}

std::string hex64(uint64_t v) {
  char buf[17];
  std::snprintf(buf, sizeof buf, "%016llx", static_cast<unsigned long long>(v));
  return buf;
}

// "<isa> <packet> | <compiler>": the conditions under which a hash is reproducible.
// ISA, packet, compiler and CPU model: three machines with the same ISA, packet and compiler have
// rendered some of these frames to different bits, each the same in every run, for reasons not
// found (frame-hashes.txt), so the hashes are recorded per CPU model too.
std::string platform_key() {
  const PacketLayout p = detect_packet_layout();
  std::ostringstream k;
  k << isa_name(p) << " " << p.w << "x" << p.h << " | " <<
#if defined(__clang__)
      "clang "
#elif defined(__GNUC__)
      "gcc "
#endif
    << __VERSION__ << " | " << app::cpu_model();
  return k.str();
}

// Asks for a still that refines to `n` samples (its first frame is the session's `seed`) and
// checks the last refinement against the direct average: tiles of several nodes, averaged
// where they are composed, give the same bytes as one renderer.
void check_refined(ProtoClient& c, const SharedScene& s, uint32_t seed, uint32_t n, const std::function<std::string()>& context) {
  const size_t k = s.camera_index(1);
  REQUIRE(c.send({protocol::Refine{n}, protocol::SetCamera{s.loop.camera(k)}, protocol::RenderRequest{7}}));
  protocol::Frame last;
  uint32_t frames = 0;
  while (auto f = c.next<protocol::Frame>(60000)) {
    ++frames;
    REQUIRE(f->frame == 7);
    last = std::move(*f);
    if (last.samples >= n) break;
  }
  INFO(s.name << " refined still, " << frames << " frames; " << context());
  REQUIRE(frames > 0);
  CHECK(last.refined);
  REQUIRE(last.samples == n);
  const std::vector<uint8_t> want = encoded(direct_refined(s, k, seed, n), DisplayKind::jpeg);
  CHECK(last.payload == want);
  // Converged: no further frame comes.
  CHECK_FALSE(c.next<protocol::Frame>(500));
}

// Checks the frames one client receives against the direct renders. `first_seq` is the
// session's sequence number of the client's first frame (sessions count from 1). The first
// frame waits for the whole scene: `first_ms` allows for it.
void check_stream(ProtoClient& c, const SharedScene& s, DisplayKind display, uint32_t first_seq,
                  const std::function<std::string()>& context, int first_ms = 20000) {
  for (size_t i = 0; i < kFrames; ++i) {
    const size_t k = s.camera_index(i);
    const auto t0 = std::chrono::steady_clock::now();
    auto f = c.render(s.loop.camera(k), uint32_t(1000 + i), i == 0 ? first_ms : 20000);
    const double took = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    INFO(s.name << " display " << int(display) << " camera " << k << " (waited " << took << " s); " << context());
    REQUIRE(f);
    REQUIRE(f->width == W);
    REQUIRE(f->height == H);
    const std::vector<uint8_t> want = encoded(direct(s, k, first_seq + uint32_t(i)), display);
    INFO("frame " << f->payload.size() << " bytes, hash " << hex64(fnv1a(f->payload)) << "; direct render "
                  << want.size() << " bytes, hash " << hex64(fnv1a(want)));
    CHECK(f->payload == want);
  }
}

void single_node(const std::string& name) {
  const SharedScene& s = shared_scene(name);
  TestNode node;
  for (DisplayKind display : {DisplayKind::jpeg, DisplayKind::s3tc}) {
    ProtoClient c;
    REQUIRE(c.connect(node.port()));
    REQUIRE(c.handshake(display, W, H, kQuality));
    REQUIRE(c.upload(s.scene.scene));
    REQUIRE(c.send({protocol::Settings{uint32_t(kAo), uint32_t(kDepth)}}));
    check_stream(c, s, display, 1, [] { return std::string("single node"); });
    if (display == DisplayKind::jpeg && name == "pavilion")
      check_refined(c, s, 1 + uint32_t(kFrames), 5, [] { return std::string("single node"); });
    c.ws.close();
  }
}

void cluster(const std::string& name) {
  const SharedScene& s = shared_scene(name);
  ServeNode w1({"--no-http", "--cluster-port", "0", "--tessera.name=w1"});
  ServeNode w2({"--no-http", "--cluster-port", "0", "--tessera.name=w2"});
  ServeNode m({"--port", "0", "--children", w1.addr() + "," + w2.addr()});
  REQUIRE(wait_for([&] { return m.p->err_count("\"child_connected\"") == 2; }, 20000));
  ProtoClient c;
  REQUIRE(c.connect(m.http));
  auto hs = c.handshake(DisplayKind::jpeg, W, H, kQuality);
  REQUIRE(hs);
  REQUIRE(hs->nodes == 3);
  REQUIRE(c.upload(s.scene.scene));
  REQUIRE(c.send({protocol::Settings{uint32_t(kAo), uint32_t(kDepth)}}));
  // The first frame of a tree: three processes each decode the scene and build its BVH (the
  // master then renders the parts of workers still building). On a loaded 2-core CI machine,
  // beside other tests, the kitchen took over 20 s; 90 s bounds a hang, not a speed.
  check_stream(
      c, s, DisplayKind::jpeg, 1,
      [&] {
        const std::string& e = m.p->err();
        return "master stderr tail: " + e.substr(e.size() > 2000 ? e.size() - 2000 : 0);
      },
      90000);
  // Every frame was split over the three nodes. The first may come late from the workers, which
  // build the whole scene first (the kitchen takes about 3 s here on one thread, the task
  // timeout): the master then renders their parts, and they are used again once they have
  // answered. Slow is not lost: no worker was dropped and opened again with the whole scene.
  if (name == "pavilion")
    check_refined(c, s, 1 + uint32_t(kFrames), 5, [&] {
      const std::string& e = m.p->err();
      return "master stderr tail: " + e.substr(e.size() > 2000 ? e.size() - 2000 : 0);
    });
  CHECK(m.p->err_count("\"cluster_frame\"") >= kFrames);
  CHECK(m.p->err_count("\"recovered\": 0,") >= 1);
  CHECK(m.p->err_count("\"node_lost\"") == 0);
}

// The recorded hashes: lines "<platform key>\t<scene>\t<camera>\t<seq>\t<hash>". A frame may
// have more than one: machines with the same key have given different bits (frame-hashes.txt).
std::map<std::string, std::set<std::string>> recorded(const std::string& key) {
  std::map<std::string, std::set<std::string>> out;
  std::ifstream f(std::string(TESSERA_GOLDEN_DIR) + "/frame-hashes.txt");
  std::string line;
  while (std::getline(f, line)) {
    if (line.empty() || line[0] == '#') continue;
    auto tab = line.find('\t');
    if (tab == std::string::npos || line.substr(0, tab) != key) continue;
    auto last = line.rfind('\t');
    out[line.substr(tab + 1, last - tab - 1)].insert(line.substr(last + 1));
  }
  return out;
}

}  // namespace

TEST_CASE("Frames of one node are byte-identical to the direct render: pavilion", "[identity]") { single_node("pavilion"); }
TEST_CASE("Frames of one node are byte-identical to the direct render: living-room", "[identity]") {
  single_node("living-room");
}
TEST_CASE("Frames of one node are byte-identical to the direct render: kitchen", "[identity]") { single_node("kitchen"); }

TEST_CASE("Frames composed by a master and two workers are byte-identical to the direct render: pavilion",
          "[identity][cluster]") {
  cluster("pavilion");
}
TEST_CASE("Frames composed by a master and two workers are byte-identical to the direct render: living-room",
          "[identity][cluster]") {
  cluster("living-room");
}
TEST_CASE("Frames composed by a master and two workers are byte-identical to the direct render: kitchen",
          "[identity][cluster]") {
  cluster("kitchen");
}

TEST_CASE("The direct renders hash as recorded for this ISA and compiler", "[identity][hash]") {
  const std::string key = platform_key();
  const auto want = recorded(key);
  std::string lines;
  size_t compared = 0;
  for (const char* name : {"pavilion", "living-room", "kitchen"}) {
    const SharedScene& s = shared_scene(name);
    for (size_t i = 0; i < kFrames; ++i) {
      const size_t k = s.camera_index(i);
      const uint32_t seq = uint32_t(i + 1);
      const std::string id = std::string(name) + "\t" + std::to_string(k) + "\t" + std::to_string(seq);
      const std::string got = hex64(fnv1a(direct(s, k, seq).rgba));
      lines += key + "\t" + id + "\t" + got + "\n";
      // The AO seed shows in the image, so the frame-number checks above mean something.
      // (The kitchen has no sky ambient, so AO does not show there.)
      if (i == 0 && max_component(s.scene.scene.environment().ambient) > 0)
        CHECK(got != hex64(fnv1a(direct(s, k, seq + 1).rgba)));
      if (auto it = want.find(id); it != want.end()) {
        INFO(key << ": " << name << " camera " << k << " frame " << seq << " hashes to " << got);
        CHECK(it->second.count(got) == 1);
        ++compared;
      }
    }
  }
  if (compared == 0) {
    if (const char* u = std::getenv("TESSERA_UPDATE_GOLDEN"); u && std::string(u) == "1") {
      std::ofstream(std::string(TESSERA_GOLDEN_DIR) + "/frame-hashes.txt", std::ios::app) << lines;
      WARN("frame hashes recorded for " << key);
    } else {
      WARN("no frame hashes recorded for " << key << "; TESSERA_UPDATE_GOLDEN=1 appends:\n" << lines);
    }
  } else {
    CHECK(compared == 3 * kFrames);
  }
}
