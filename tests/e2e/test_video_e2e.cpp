// End to end, the H.264 display (docs/protocol.md, "Video"): a real node (in-process) and a real
// WebSocket client. The pavilion's frames along its camera loop decode with OpenH264's decoder
// to the ray tracer's direct render; the stream starts with a keyframe and has one again when
// the client asks and after a resize, and nowhere else; a lower bitrate gives smaller frames;
// bad video records get clear, non-fatal errors while another client is unaffected; a size
// beyond H.264's level 5.2 gets an error for each frame, not a broken stream.
#include <catch2/catch.hpp>

#include <algorithm>

#include "codecs/h264.h"
#include "tests/e2e/node_fixture.h"

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
