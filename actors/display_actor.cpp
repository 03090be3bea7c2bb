// Display channel actor: composes tiles, has the encoder encode the frame, sends it.
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstring>
#include <optional>

#include <caf/all.hpp>

#include "actors/node.h"
#include "codecs/video_rate.h"
#include "core/image.h"

namespace tessera {
namespace {

using protocol::DisplayKind;

struct display_state {
  std::shared_ptr<ClientSink> sink;
  encoder_actor encoder;
  std::shared_ptr<const NodeSettings> settings;
  uint64_t session = 0;
  uint64_t frames = 0, bytes = 0;
  int64_t t0_ns = 0;
  // The Stats window: frames sent and their pipeline times since the last Stats record.
  int64_t window_start_ns = 0;  // 0: no frame sent yet
  uint32_t window_frames = 0;
  double window_pipeline_ms = 0;
  // At most one frame at the encoder and one waiting for it: rendering runs ahead of encoding
  // (the next frame renders while this one encodes), and a client that asks faster than its
  // frames encode (a 640x360 DXT1 frame takes longer to encode than a small scene takes to
  // render) must not queue rendered frames without bound. A newer frame replaces the waiting
  // one, which is counted as dropped, as the connection does with frames the client has not
  // read (net/server.cpp).
  //
  // An H.264 stream cannot lose a frame (each is predicted from the one before), so the
  // connection must never replace one. Instead the display holds back: it encodes the next
  // frame only once the connection has written the last one (ClientSink::frames_unsent() is
  // 0), and meanwhile the newest rendered frame waits here, replacing older ones (dropped
  // before encoding, so the stream stays whole). A slow link thus gets fewer frames, each
  // the newest, and never a queue.
  bool encoding = false;
  std::optional<EncodeJob> waiting;
  uint64_t replaced = 0;
  // Bandwidth adaptation (codecs/video_rate.h): the stream's target bitrate, which the link's
  // measured throughput (ClientSink::link_kbps) holds below the client's or the node's while
  // frames wait for the link (ClientSink::frames_waited grows, or link_saturated), and the
  // count last seen.
  VideoRateControl rate;
  uint32_t frames_waited = 0;

  static inline const char* name = "tessera.display";
};


constexpr int64_t kStatsPeriodNs = 1'000'000'000;

// About once per second while frames flow: after a frame is sent, a Stats record covering the
// frames sent since the previous one (fps, mean pipeline time) and the session's totals.
void maybe_send_stats(display_state& st, const FrameMeta& m, int64_t sent_ns, double pipeline_ms) {
  if (st.window_start_ns == 0) {  // the first frame opens the first window
    st.window_start_ns = sent_ns;
    return;
  }
  st.window_frames++;
  st.window_pipeline_ms += pipeline_ms;
  const int64_t span = sent_ns - st.window_start_ns;
  if (span < kStatsPeriodNs) return;
  protocol::Stats s;
  s.frames = uint32_t(st.frames);
  s.dropped = uint32_t(m.dropped + st.sink->frames_dropped() + st.replaced);
  s.bytes_sent = st.bytes;
  s.scene_bytes = m.scene_bytes;
  s.triangles = m.triangles;
  s.nodes = m.nodes;
  // Frames sent after the one that opened the window, over the window's length.
  s.fps = float(double(st.window_frames) * 1e9 / double(span));
  s.mean_pipeline_ms = float(st.window_pipeline_ms / st.window_frames);
  st.sink->send(protocol::encode(protocol::ServerRecord{s}));
  st.window_start_ns = sent_ns;
  st.window_frames = 0;
  st.window_pipeline_ms = 0;
}

// Composes the tiles into one RGBA image (a single full-size tile is moved, not copied).
std::vector<uint8_t> compose(FrameTiles& ft) {
  const auto& m = ft.meta;
  if (ft.tiles.size() == 1 && ft.tiles[0].pixels == Rect{0, 0, m.width, m.height})
    return std::move(ft.tiles[0].rgba);
  Image img(m.width, m.height);
  for (auto& t : ft.tiles) {
    const Rect& r = t.pixels;
    if (r.empty() || t.rgba.size() != size_t(r.width()) * r.height() * 4) continue;
    if (!Rect{0, 0, m.width, m.height}.contains(r)) continue;
    for (int32_t y = 0; y < r.height(); ++y)
      std::memcpy(img.pixel(r.x0, r.y0 + y), t.rgba.data() + size_t(y) * r.width() * 4, size_t(r.width()) * 4);
  }
  return std::move(img.rgba);
}

using display_ptr = display_actor::stateful_pointer<display_state>;

// Sends one encoded frame (or its error) to the client, with its stats and log line.
void send_encoded(display_state& st, EncodedFrame& ef) {
  const auto& m = ef.meta;
  if (!ef.error.empty()) {
    protocol::ErrorReply e{protocol::ErrorCode::internal, false, protocol::kNoRecord,
                           "frame " + std::to_string(m.client_frame) + ": " + ef.error};
    st.sink->send(protocol::encode(protocol::ServerRecord{e}));
    Event ev(Ev::error, "encode");
    ev.scope = {{"session", st.session}};
    node_log(*st.settings, std::move(ev));
    return;
  }
  const bool mjpeg = DisplayKind(m.display) == DisplayKind::mjpeg;
  protocol::Frame f;
  f.frame = m.client_frame;
  f.width = m.width;
  f.height = m.height;
  f.encoding = DisplayKind(m.display) == DisplayKind::s3tc   ? protocol::FrameEncoding::dxt1
               : DisplayKind(m.display) == DisplayKind::h264 ? protocol::FrameEncoding::h264
                                                             : protocol::FrameEncoding::jpeg;
  f.refined = m.refined;
  f.converged = m.refined && m.converged;
  f.samples = uint16_t(std::min<uint32_t>(m.samples, 65535));
  f.timings.kernel_ms = float(m.kernel_ms);
  f.timings.rendering_ms = float(m.rendering_ms);
  f.timings.sat_ms = float(m.sat_ms);
  f.timings.tiling_ms = float(m.tiling_ms);
  f.timings.encode_ms = float(ef.encode_ms);
  const size_t payload = ef.message.size() - ef.header_bytes;
  const int64_t sent_ns = steady_ns();
  f.timings.pipeline_ms = float(double(sent_ns - m.render_end_ns) / 1e6);
  std::vector<uint8_t> header;
  header.reserve(ef.header_bytes);
  size_t bytes = 0;
  if (mjpeg) {
    // The JPEG goes to the MJPEG stream; the WebSocket gets the Frame record
    // with its timings and an empty payload.
    auto jpeg = std::make_shared<std::vector<uint8_t>>(ef.message.begin() + ef.header_bytes, ef.message.end());
    bytes = jpeg->size();
    st.sink->send_mjpeg(std::move(jpeg), f.frame);
    protocol::encode_frame_header(f, 0, header);
    st.sink->send_frame(std::move(header));
  } else {
    protocol::encode_frame_header(f, payload, header);
    std::memcpy(ef.message.data(), header.data(), ef.header_bytes);
    bytes = ef.message.size();
    st.sink->send_frame(std::move(ef.message));
  }
  st.frames++;
  st.bytes += bytes;
  maybe_send_stats(st, m, sent_ns, f.timings.pipeline_ms);
  auto rel = [&](int64_t ns) { return double(ns - st.t0_ns) / 1e6; };
  Event e(Ev::frame, m.client_frame);
  e.scope = {{"session", st.session}};
  e.with("seq", m.seq).with("width", m.width).with("height", m.height);
  e.with("display", mjpeg                                          ? "mjpeg"
                    : f.encoding == protocol::FrameEncoding::dxt1 ? "s3tc"
                    : f.encoding == protocol::FrameEncoding::h264 ? "h264"
                                                                  : "jpeg");
  if (f.encoding == protocol::FrameEncoding::h264) {
    // The bitrate this frame was encoded for (bandwidth adaptation), and the link as measured.
    e.with("keyframe", ef.keyframe).with("target_kbps", m.video_kbps).with("link_kbps", st.sink->link_kbps());
  }
  e.with("kernel_ms", Json::number(m.kernel_ms)).with("rendering_ms", Json::number(m.rendering_ms));
  e.with("sat_ms", Json::number(m.sat_ms)).with("tiling_ms", Json::number(m.tiling_ms));
  e.with("encode_ms", Json::number(ef.encode_ms)).with("pipeline_ms", Json::number(f.timings.pipeline_ms));
  e.with("bytes", bytes).with("ao", m.ao_samples).with("depth", m.max_depth);
  if (m.samples > 1 || m.refined) e.with("samples", m.samples).with("refined", m.refined);
  if (m.converged) e.with("converged", true);
  if (m.blocks > 0) e.with("round", m.round).with("blocks", m.blocks);
  if (m.estimated_db > 0)
    e.with("estimated_db", Json::number(m.estimated_db)).with("denoised", m.denoised).with("denoise_ms", Json::number(m.denoise_ms));
  e.with("render_start_ms", Json::number(rel(m.render_start_ns)));
  e.with("render_end_ms", Json::number(rel(m.render_end_ns)));
  e.with("encode_start_ms", Json::number(rel(ef.encode_start_ns)));
  e.with("encode_end_ms", Json::number(rel(ef.encode_end_ns)));
  e.with("sent_ms", Json::number(rel(sent_ns)));
  node_log(*st.settings, std::move(e));
}

bool is_video(const EncodeJob& job) { return DisplayKind(job.meta.display) == DisplayKind::h264; }

void encode(display_ptr self, EncodeJob job);

// The waiting frame goes to the encoder, if there is one and (H.264) the connection has
// written the last frame; otherwise the sink's on_frame_gone brings a tick_atom when it has.
void next(display_ptr self) {
  auto& st = self->state;
  if (st.encoding || !st.waiting) return;
  if (is_video(*st.waiting) && st.sink->frames_unsent() > 0) return;
  EncodeJob job = std::move(*st.waiting);
  st.waiting.reset();
  if (is_video(job)) {
    // meta.video_kbps: the ceiling (client or node) in, the target out (the encoder's and the log's).
    const uint32_t waited = st.sink->frames_waited();
    // The link bounds the frames: one waited in the node since the last encode, or the kernel
    // has lately held bytes back most of the time.
    const bool link_bound = waited != st.frames_waited || st.sink->link_saturated();
    job.meta.video_kbps = st.rate.update(steady_ns(), job.meta.video_kbps, st.sink->link_kbps(), link_bound);
    st.frames_waited = waited;
  }
  encode(self, std::move(job));
}

// Hands `job` to the encoder; when it is back, the waiting frame (if any) goes next.
void encode(display_ptr self, EncodeJob job) {
  self->state.encoding = true;
  // Replies arrive in request order (one encoder, one requester), so frames go out in order.
  self->request(self->state.encoder, caf::infinite, encode_atom::value, std::move(job))
      .then([=](EncodedFrame& ef) {
        auto& st = self->state;
        st.encoding = false;
        send_encoded(st, ef);
        next(self);
      });
}

display_actor::behavior_type display_impl(display_ptr self, std::shared_ptr<ClientSink> sink, encoder_actor encoder,
                                          std::shared_ptr<const NodeSettings> settings, uint64_t session) {
  auto& st = self->state;
  st.sink = std::move(sink);
  st.encoder = encoder;
  st.settings = std::move(settings);
  st.session = session;
  st.t0_ns = steady_ns();
  // A frame left the connection: a waiting H.264 frame may go (next()).
  st.sink->on_frame_gone([weak = caf::actor_cast<caf::weak_actor_ptr>(self)] {
    if (auto strong = caf::actor_cast<caf::strong_actor_ptr>(weak))
      caf::anon_send(caf::actor_cast<display_actor>(strong), tick_atom::value);
  });
  return {
      [=](display_atom, FrameTiles& ft) {
        auto& st = self->state;
        EncodeJob job;
        job.meta = ft.meta;
        job.rgba = compose(ft);
        if (st.waiting) st.replaced++;
        st.waiting = std::move(job);
        next(self);
      },
      [=](tick_atom) { next(self); },
  };
}

}  // namespace

display_actor spawn_display(caf::actor_system& sys, std::shared_ptr<ClientSink> sink, encoder_actor encoder,
                            std::shared_ptr<const NodeSettings> settings, uint64_t session_id) {
  return sys.spawn(display_impl, std::move(sink), encoder, std::move(settings), session_id);
}

}  // namespace tessera
