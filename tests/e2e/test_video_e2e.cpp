// End to end, the H.264 display (docs/protocol.md, "Video"): a real node (in-process) and a real
// WebSocket client. The pavilion's frames along its camera loop decode with OpenH264's decoder
// to the ray tracer's direct render; the stream starts with a keyframe and has one again when
// the client asks and after a resize, and nowhere else; a lower bitrate gives smaller frames;
// bad video records get clear, non-fatal errors while another client is unaffected; a size
// beyond H.264's level 5.2 gets an error for each frame, not a broken stream. A client that
// reads slowly gets a stream fitted to its link, and the full bitrate again once it reads fast
// (bandwidth adaptation).
#include <catch2/catch.hpp>

#include <netinet/in.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <arpa/inet.h>

#include <algorithm>
#include <cstdio>
#include <map>

#include "codecs/h264.h"
#include "tests/e2e/node_fixture.h"
#include "net/ws_frame.h"

using namespace tessera;
using namespace tessera::test;
using protocol::DisplayKind;
using protocol::ErrorCode;

namespace {

constexpr int W = 320, H = 180;

bool keyframe(const protocol::Frame& f) {
  const auto t = h264_nal_types(f.payload.data(), f.payload.size());
  return std::find(t.begin(), t.end(), 5) != t.end();
}

}  // namespace

TEST_CASE("H.264 frames decode to the ray tracer's picture, with keyframes first, when asked and after a resize",
          "[e2e][video]") {
  TestNode node;
  ProtoClient c;
  REQUIRE(c.connect(node.port()));
  auto hs = c.handshake(DisplayKind::h264, W, H);
  REQUIRE(hs);
  CHECK(hs->display == DisplayKind::h264);
  REQUIRE(c.upload(pavilion().scene));
  REQUIRE(c.send({protocol::Settings{2, 4}}));
  H264Decoder dec;
  uint32_t seq = 0;
  auto frame = [&](size_t k, uint32_t n, int w, int h, std::vector<protocol::ClientRecord> before = {}) {
    before.push_back(protocol::SetCamera{pavilion_loop().camera(k)});
    before.push_back(protocol::RenderRequest{n});
    REQUIRE(c.send(before));
    auto f = c.next<protocol::Frame>();
    REQUIRE(f);
    ++seq;
    CHECK(f->frame == n);
    CHECK(f->encoding == protocol::FrameEncoding::h264);
    CHECK(f->width == w);
    CHECK(f->height == h);
    CHECK(f->timings.encode_ms > 0);
    Image got;
    std::string err;
    REQUIRE(dec.decode(f->payload.data(), f->payload.size(), got, err, w, h));
    INFO(err);
    return std::make_pair(*f, got);
  };
  // Along the camera loop: each frame decodes, and shows what the ray tracer renders.
  for (uint32_t i = 0; i < 4; ++i) {
    const size_t k = i * 10;
    auto [f, got] = frame(k, 100 + i, W, H);
    CHECK(keyframe(f) == (i == 0));
    const double psnr = compare(got, render_direct(pavilion().scene, pavilion_loop().camera(k), W, H, 2, seq)).psnr;
    INFO("frame " << i << " PSNR " << psnr << ", " << f.payload.size() << " bytes");
    CHECK(psnr >= 30);
  }
  // A keyframe on request (the record goes with the render request).
  CHECK(keyframe(frame(40, 200, W, H, {protocol::Video{0, true}}).first));
  CHECK_FALSE(keyframe(frame(41, 201, W, H).first));
  // A resize starts a new stream: a keyframe at the new size (odd, so the picture is cropped).
  auto resized = frame(42, 202, 241, 135, {protocol::Resolution{241, 135}});
  CHECK(keyframe(resized.first));
  CHECK(resized.second.width == 241);
  CHECK(compare(resized.second, render_direct(pavilion().scene, pavilion_loop().camera(42), 241, 135, 2, seq)).psnr >= 30);
  CHECK_FALSE(keyframe(frame(43, 203, 241, 135).first));
  // A lower bitrate gives smaller frames (the same view, so only the AO pattern changes).
  auto mean_bytes = [&](uint32_t first, std::vector<protocol::ClientRecord> before) {
    size_t bytes = 0;
    for (uint32_t i = 0; i < 6; ++i) {
      auto f = frame(50, first + i, 241, 135, i == 0 ? before : std::vector<protocol::ClientRecord>{}).first;
      if (i >= 2) bytes += f.payload.size();
      CHECK_FALSE(keyframe(f));
    }
    return bytes / 4;
  };
  const size_t high = mean_bytes(300, {protocol::Video{20000, false}});
  const size_t low = mean_bytes(400, {protocol::Video{100, false}});
  INFO("mean P-frame bytes at 20 Mbit/s " << high << ", at 100 kbit/s " << low);
  CHECK(low < high);
  // Events reach the node's log through its logger actor: the last frame's may still be on its way.
  CHECK(wait_for([&] { return node.count(Ev::frame, [](const Event& e) { return has(e, "display", "h264"); }) >= 20; }));
  // The handshake's event names the display (its value: an object of the accepted settings).
  CHECK(node.count(Ev::handshake, [](const Event& e) {
    for (auto& [k, v] : e.value.members())
      if (k == "display") return v.type() == Json::Type::string && v.as_string() == "h264";
    return false;
  }) == 1);
}

TEST_CASE("Bad video records get clear errors, the session goes on, and another client is unaffected",
          "[e2e][video][fault]") {
  TestNode node;
  ProtoClient a, b;
  REQUIRE(a.connect(node.port()));
  REQUIRE(b.connect(node.port()));
  REQUIRE(a.handshake(DisplayKind::h264, W, H));
  REQUIRE(b.handshake(DisplayKind::jpeg, W, H));
  REQUIRE(a.upload(pavilion().scene));
  REQUIRE(b.upload(pavilion().scene));
  // A bitrate below 100 kbit/s (0 means unchanged) and above 200 Mbit/s.
  for (uint32_t kbps : {50u, 200001u}) {
    REQUIRE(a.send({protocol::Video{kbps, false}}));
    auto e = a.next<protocol::ErrorReply>();
    REQUIRE(e);
    CHECK(e->code == ErrorCode::out_of_range);
    CHECK_FALSE(e->fatal);
    CHECK(e->message.find("bitrate_kbps") != std::string::npos);
  }
  auto fa = a.render(pavilion_loop().camera(3), 1);
  auto fb = b.render(pavilion_loop().camera(3), 2);
  REQUIRE(fa);
  REQUIRE(fb);
  CHECK(fa->encoding == protocol::FrameEncoding::h264);
  CHECK(fb->encoding == protocol::FrameEncoding::jpeg);
  H264Decoder dec;
  Image got;
  std::string err;
  REQUIRE(dec.decode(fa->payload.data(), fa->payload.size(), got, err, W, H));
  CHECK(compare(got, decode_jpeg(fb->payload)).psnr > 30);
  CHECK(wait_for([&] { return node.count(Ev::error) >= 2; }));
}

TEST_CASE("A size beyond H.264 level 5.2 gets an error for each frame, and a size within it frames again",
          "[e2e][video][fault]") {
  TestNode node;
  ProtoClient c;
  REQUIRE(c.connect(node.port()));
  // 4112 x 2304 is 257 x 144 = 37,008 macroblocks (level 5.2 allows 36,864); nothing uploaded,
  // so the frame is the background and renders at once.
  REQUIRE(c.handshake(DisplayKind::h264, 4112, 2304));
  REQUIRE(c.send({protocol::RenderRequest{1}}));
  auto e = c.next<protocol::ErrorReply>();
  REQUIRE(e);
  CHECK_FALSE(e->fatal);
  CHECK(e->message.find("level 5.2") != std::string::npos);
  REQUIRE(c.send({protocol::Resolution{64, 48}, protocol::RenderRequest{2}}));
  auto f = c.next<protocol::Frame>();
  REQUIRE(f);
  CHECK(f->frame == 2);
  CHECK(keyframe(*f));
  H264Decoder dec;
  Image got;
  std::string err;
  CHECK(dec.decode(f->payload.data(), f->payload.size(), got, err, 64, 48));
}

namespace {

// A WebSocket client on a plain socket that reads at most `rate` bytes a second (0: as fast as
// it can), with a small receive buffer: a slow link, as the node sees one. Single-threaded:
// pump() reads what the rate allows and decodes the frames it completes.
struct ThrottledClient {
  int fd = -1;
  double rate = 0;              // bytes/s; 0 = unthrottled
  double allowance = 0;         // bytes the rate allows now
  std::chrono::steady_clock::time_point last = std::chrono::steady_clock::now();
  std::vector<uint8_t> in;      // received, not yet a whole WebSocket message
  uint64_t bytes_read = 0;
  struct Got {
    protocol::Frame frame;
    std::chrono::steady_clock::time_point at;
  };
  std::vector<Got> frames;
  std::vector<protocol::ErrorReply> errors;

  ~ThrottledClient() {
    if (fd >= 0) ::close(fd);
  }
  bool connect(uint16_t port, int rcvbuf) {
    fd = ::socket(AF_INET, SOCK_STREAM, 0);
    if (fd < 0) return false;
    ::setsockopt(fd, SOL_SOCKET, SO_RCVBUF, &rcvbuf, sizeof rcvbuf);  // before connect: the window
    sockaddr_in a{};
    a.sin_family = AF_INET;
    a.sin_port = htons(port);
    a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    if (::connect(fd, reinterpret_cast<sockaddr*>(&a), sizeof a) != 0) return false;
    const std::string up =
        "GET /ws HTTP/1.1\r\nHost: 127.0.0.1\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n"
        "Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\nSec-WebSocket-Version: 13\r\n\r\n";
    if (!write(up.data(), up.size())) return false;
    std::string head;  // the 101 response, a byte at a time (nothing after it is consumed)
    while (head.find("\r\n\r\n") == std::string::npos) {
      pollfd p{fd, POLLIN, 0};
      char c;
      if (::poll(&p, 1, 5000) <= 0 || ::recv(fd, &c, 1, 0) != 1) return false;
      head += c;
    }
    return head.compare(0, 12, "HTTP/1.1 101") == 0;
  }
  bool write(const void* p, size_t n) {
    const auto* b = static_cast<const uint8_t*>(p);
    while (n > 0) {  // blocking: the upload may fill the node's receive buffer for a moment
      const ssize_t k = ::send(fd, b, n, MSG_NOSIGNAL);
      if (k <= 0) return false;
      b += k;
      n -= size_t(k);
    }
    return true;
  }
  // One binary message, masked as a client must.
  bool send(const std::vector<uint8_t>& payload) {
    const uint8_t mask[4] = {0x3a, 0x5c, 0x71, 0x0e};
    const std::vector<uint8_t> f = masked_ws_frame(payload, mask);
    return write(f.data(), f.size());
  }
  bool send(const std::vector<protocol::ClientRecord>& recs) { return send(protocol::encode(recs)); }
  // Reads for up to `ms` milliseconds, no faster than the rate; decodes each whole message.
  void pump(int ms) {
    const auto end = std::chrono::steady_clock::now() + std::chrono::milliseconds(ms);
    while (std::chrono::steady_clock::now() < end) {
      const auto now = std::chrono::steady_clock::now();
      allowance = std::min(allowance + rate * std::chrono::duration<double>(now - last).count(), 4096.0);
      last = now;
      size_t want = 65536;
      if (rate > 0) {
        if (allowance < 256) {  // read in pieces of at least 256 bytes, every few ms
          std::this_thread::sleep_for(std::chrono::milliseconds(2));
          continue;
        }
        want = size_t(allowance);
      }
      pollfd p{fd, POLLIN, 0};
      if (::poll(&p, 1, 2) <= 0) continue;
      uint8_t buf[65536];
      const ssize_t k = ::recv(fd, buf, std::min(want, sizeof buf), 0);
      if (k <= 0) return;
      allowance -= double(k);
      bytes_read += uint64_t(k);
      in.insert(in.end(), buf, buf + k);
      decode();
    }
  }
  void decode() {
    while (in.size() >= 2) {
      size_t len = in[1] & 0x7f, at = 2;
      if (len == 126) {
        if (in.size() < 4) return;
        len = size_t(in[2]) << 8 | in[3];
        at = 4;
      } else if (len == 127) {
        if (in.size() < 10) return;
        len = 0;
        for (int i = 0; i < 8; ++i) len = len << 8 | in[2 + i];
        at = 10;
      }
      if (in.size() < at + len) return;
      if ((in[0] & 0x0f) == 0x2) {  // binary: protocol records
        auto recs = protocol::decode_server(in.data() + at, len, protocol::Limits{});
        if (recs)
          for (auto& r : recs.value()) {
            if (auto* f = std::get_if<protocol::Frame>(&r)) frames.push_back({std::move(*f), std::chrono::steady_clock::now()});
            if (auto* e = std::get_if<protocol::ErrorReply>(&r)) errors.push_back(*e);
          }
      }
      in.erase(in.begin(), in.begin() + long(at + len));
    }
  }
};

// The target bitrates of the node's H.264 frames so far, in order (the frame events' target_kbps).
std::vector<uint32_t> targets(TestNode& node) {
  std::vector<uint32_t> out;
  for (auto& e : node.events(Ev::frame))
    if (const Json* t = e.field("target_kbps")) out.push_back(uint32_t(t->as_int()));
  return out;
}

}  // namespace

TEST_CASE("A client on a slow link gets a stream fitted to it with bounded latency, and the full bitrate once it reads fast",
          "[e2e][video]") {
  TestNode node;
  ThrottledClient c;
  // A 4 KiB receive buffer (the kernel doubles it): a small window, so that the link's
  // throughput is the reader's rate without long stalls.
  REQUIRE(c.connect(node.port(), 4 << 10));
  protocol::Handshake hs;
  hs.display = DisplayKind::h264;
  hs.width = W;
  hs.height = H;
  REQUIRE(c.send({hs}));
  protocol::SceneRecordOptions o;
  o.resolution = false;
  for (auto& m : protocol::pack_messages(protocol::scene_to_records(pavilion().scene, o), 8u << 20)) REQUIRE(c.send(m));
  constexpr uint32_t kCeiling = 4000;  // the client's bitrate: the ceiling of the target
  REQUIRE(c.send({protocol::Settings{2, 4}, protocol::Video{kCeiling, false}}));
  // The camera moves along the loop and the client asks for a frame every 33 ms (as a page
  // does while the view moves), whatever comes back: the link decides what it gets.
  std::map<uint32_t, std::chrono::steady_clock::time_point> asked;
  uint32_t n = 0;
  auto run = [&](double seconds) {
    const auto end = std::chrono::steady_clock::now() + std::chrono::duration<double>(seconds);
    while (std::chrono::steady_clock::now() < end) {
      ++n;
      asked[n] = std::chrono::steady_clock::now();
      REQUIRE(c.send({protocol::SetCamera{pavilion_loop().camera(n)}, protocol::RenderRequest{n}}));
      c.pump(33);
    }
  };
  // Slow: 64 KB/s (512 kbit/s), an eighth of the ceiling.
  constexpr double kSlow = 64000;
  c.rate = kSlow;
  // 10 s of wall time whatever the build: the law's times are wall-clock (hold, rises), and a
  // sanitizer build only gives fewer frames in it.
  const double slow_s = 10;
  run(slow_s / 2);
  const size_t half = c.frames.size();
  const size_t half_targets = targets(node).size();
  run(slow_s / 2);
  const size_t slow_frames = c.frames.size() - half;
  double worst_ms = 0;  // latency: from asking for a frame to having it, in the second half
  for (size_t i = half; i < c.frames.size(); ++i) {
    auto it = asked.find(c.frames[i].frame.frame);
    REQUIRE(it != asked.end());
    worst_ms = std::max(worst_ms, std::chrono::duration<double, std::milli>(c.frames[i].at - it->second).count());
  }
  auto slow_targets = targets(node);
  REQUIRE(slow_targets.size() > half_targets);
  const std::vector<uint32_t> late(slow_targets.begin() + long(half_targets), slow_targets.end());
  const uint32_t late_max = *std::max_element(late.begin(), late.end());
  const uint32_t late_min = *std::min_element(late.begin(), late.end());
  double late_mean = 0;
  for (uint32_t t : late) late_mean += double(t) / double(late.size());
  // What the node measured of the link meanwhile (0: not measured lately), for the message.
  std::string measured;
  {
    size_t k = 0;  // the H.264 frames' events (those with a target), as targets() counts them
    for (auto& e : node.events(Ev::frame))
      if (e.field("target_kbps") && k++ >= half_targets)
        if (const Json* l = e.field("link_kbps")) measured += std::to_string(l->as_int()) + " ";
  }
  const double link_kbps = kSlow * 8 / 1000;
  INFO("slow phase: " << slow_frames << " frames in the second half, worst latency " << worst_ms << " ms, targets "
                      << late_min << ".." << late_max << " (mean " << late_mean << ") kbit/s for a " << link_kbps << " kbit/s link; errors "
                      << c.errors.size() << "; the link as measured, frame by frame: " << measured);
  CHECK(c.errors.empty());
  // The target fell to fit the link: it saw-tooths from 80% of the link's measured throughput
  // to a little above it (the law probes for more; measured over busy stretches, a
  // throttled reader's link can look up to ~20% faster or slower than its mean), never below
  // the protocol's minimum, and uses the link rather than starving it. Under a sanitizer the
  // node renders and encodes several times slower, so the link does not bound every frame and
  // the law probes above it (9-15 frames in the second half under ASan, means of 1.16x and
  // 1.28x the link): there the check is that the target fell well below the ceiling (7.8x).
  // The highest target may be the law's probe beyond the best throughput of the last 10 s, 10%
  // a second for 5 s (1.1^5 = 1.61x); in the Release suite beside other tests on 2 cores it
  // reached 769 and 785 kbit/s (1.50x and 1.53x) while the mean stayed at 0.71-0.79x.
  const bool sanitized = time_scale() > 1;
  CHECK(late_max <= link_kbps * (sanitized ? 2.0 : 1.65));
  CHECK(late_min >= kH264MinKbps);
  CHECK(late_mean >= link_kbps * 0.4);
  CHECK(late_mean <= link_kbps * (sanitized ? 1.75 : 1.25));
  // Frames keep coming (the link carries 10-20 of these a second), and the newest each time:
  // latency stays bounded (measured: 0.2-0.4 s) instead of growing with a queue.
  CHECK(slow_frames >= (time_scale() > 1 ? 4u : 10u));
  CHECK(worst_ms < 3000 * time_scale());
  // Fast: the reader keeps up again. The target climbs back to the ceiling, step by step
  // (from an eighth of it: 1 s of hold, 5 s of slow rises beyond the link's last throughput,
  // then about 3 s of fast ones), and not beyond.
  c.rate = 0;
  const auto t_fast = std::chrono::steady_clock::now();
  bool back = false;
  while (!back && std::chrono::steady_clock::now() - t_fast < std::chrono::seconds(20 * time_scale())) {
    run(0.5);
    auto t = targets(node);
    back = !t.empty() && t.back() == kCeiling;
  }
  const double back_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t_fast).count();
  INFO("back at the ceiling after " << back_s << " s");
  // The figures (docs/protocol.md, "Bandwidth adaptation").
  std::printf("bandwidth adaptation, %dx%d, link %.0f kbit/s: %.1f frames/s, targets %u..%u (mean %.0f) kbit/s, worst latency %.0f ms; "
              "back at the %u kbit/s ceiling %.1f s after the reader sped up\n",
              W, H, link_kbps, double(slow_frames) / (slow_s / 2), late_min, late_max, late_mean, worst_ms, kCeiling, back_s);
  CHECK(back);
  for (uint32_t t : targets(node)) CHECK(t <= kCeiling);
  // Every frame of the stream arrived and decodes in order (none was lost on the slow link).
  H264Decoder dec;
  size_t decoded = 0;
  for (auto& g : c.frames) {
    Image img;
    std::string err;
    decoded += dec.decode(g.frame.payload.data(), g.frame.payload.size(), img, err, W, H);
  }
  CHECK(decoded == c.frames.size());
}
