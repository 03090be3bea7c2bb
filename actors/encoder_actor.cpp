// Encoder actor: JPEG, DXT1 or H.264 of a composed frame, written after room for the header.
#include <algorithm>
#include <chrono>
#include <memory>

#include <caf/all.hpp>

#include "actors/node.h"
#include "codecs/dxt1.h"
#include "codecs/h264.h"
#include "codecs/jpeg.h"

namespace tessera {
namespace {

using protocol::DisplayKind;

struct encoder_state {
  JpegEncoder jpeg;
  // The session's video stream: one encoder state per session (the encoder actor is the
  // session's), made at its first H.264 frame.
  std::unique_ptr<H264Encoder> h264;
  uint32_t keyframe_requests = 0;  // the client's keyframe requests honoured so far
  int64_t last_h264_ns = 0;        // when the previous H.264 frame was encoded (its frame rate)
  double fps = 30;
  static inline const char* name = "tessera.encoder";
};


// Bytes of the message header + frame record header + frame fields (everything before the payload).
uint32_t frame_header_bytes() {
  static const uint32_t n = [] {
    std::vector<uint8_t> tmp;
    protocol::encode_frame_header(protocol::Frame{}, 0, tmp);
    return uint32_t(tmp.size());
  }();
  return n;
}

encoder_actor::behavior_type encoder_impl(encoder_actor::stateful_pointer<encoder_state> self) {
  return {
      [=](encode_atom, EncodeJob& job) -> EncodedFrame {
        EncodedFrame out;
        out.meta = job.meta;
        out.header_bytes = frame_header_bytes();
        out.encode_start_ns = steady_ns();
        const auto& m = job.meta;
        if (job.rgba.size() != size_t(m.width) * size_t(m.height) * 4) {
          out.error = "composed image has the wrong size";
        } else if (DisplayKind(m.display) == DisplayKind::s3tc) {
          Image img;
          img.width = m.width;
          img.height = m.height;
          img.rgba = std::move(job.rgba);
          dxt1_encode(img, Dxt1Fit::range, out.message, out.header_bytes);
        } else if (DisplayKind(m.display) == DisplayKind::h264) {
          auto& st = self->state;
          if (!st.h264) st.h264 = std::make_unique<H264Encoder>();
          // Rate control spreads the bitrate over the frame rate the frames actually come at.
          if (st.last_h264_ns > 0) {
            const double dt = double(out.encode_start_ns - st.last_h264_ns) / 1e9;
            if (dt > 0) st.fps = std::clamp(0.8 * st.fps + 0.2 / dt, 1.0, 120.0);
          }
          st.last_h264_ns = out.encode_start_ns;
          const bool key = m.keyframe_requests > st.keyframe_requests;
          H264Unit unit;
          std::string err;
          if (!st.h264->encode(job.rgba.data(), m.width, m.height, m.video_kbps, float(st.fps), key, out.message, unit,
                               err, out.header_bytes)) {
            out.error = err;
          } else {
            st.keyframe_requests = std::max(st.keyframe_requests, m.keyframe_requests);
            out.keyframe = unit.keyframe;
          }
        } else {
          std::string err;
          if (!self->state.jpeg.encode(job.rgba.data(), m.width, m.height, m.quality, out.message, err,
                                       out.header_bytes))
            out.error = "JPEG encoding failed: " + err;
        }
        out.encode_end_ns = steady_ns();
        out.encode_ms = double(out.encode_end_ns - out.encode_start_ns) / 1e6;
        return out;
      },
  };
}

}  // namespace

encoder_actor spawn_encoder(caf::actor_system& sys, bool detached) {
  if (detached) return sys.spawn<caf::detached>(encoder_impl);
  return sys.spawn(encoder_impl);
}

}  // namespace tessera
