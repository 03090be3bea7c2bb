#pragma once
// Bandwidth adaptation of the H.264 display (docs/protocol.md, "Video", "Bandwidth
// adaptation"): the target bitrate of a session's stream, from the ceiling the client or the
// node sets and what the connection shows of the link.
//
// The law, applied once per frame before it is encoded:
//  - The ceiling is the client's bitrate_kbps, else the node's video-kbps. The target never
//    exceeds it and never falls below kH264MinKbps (the protocol's 100 kbit/s).
//  - The frame waited for the link (the connection was still writing the frames before it when
//    it came) and the link's throughput is measured: the target falls to `fit` (80%) of that
//    throughput if it is above it (a frame that waits while the target is already below only
//    holds the target where it is); that throughput is remembered as the link's, unless the
//    link carried more within the last `memory_s` (10 s): a throughput measured low for a
//    moment (a receiver that stalled, a loaded peer) then does not hold the target low for
//    long, as a windowed maximum of delivery rates does in TCP's BBR.
//  - The frame did not wait, and no frame has waited for `hold_s` (1 s): the target rises, by
//    elapsed time (at most `max_step_s` of it per frame, so a pause in the frames does not jump
//    it), up to the ceiling: by `growth_per_s` (50%) a second up to the remembered link
//    throughput, then by `probe_per_s` (10%) a second for `probe_s` (5 s) beyond it (the link
//    signals late: socket buffers fill before frames wait), then by 50% a second again (the
//    link has grown). So a link that keeps up gets back to the ceiling step by step: from 1/8
//    of it in about 10 s.
//  - A new ceiling applies at once when the link has not held the target below the old one;
//    else the target stays (at most the new ceiling) and rises from there.
// With a link slower than the ceiling the target thus saw-tooths around the link's throughput,
// from 80% of it to a little above, one cut every few seconds, and the frames' latency stays
// bounded.
// Pure code: time and measurements are arguments (the display actor passes them).
#include <cstdint>

namespace tessera {

class VideoRateControl {
 public:
  struct Params {
    double fit = 0.8;           // a cut takes the target to this fraction of the link's throughput
    double growth_per_s = 0.5;  // relative rise per second while the link keeps up
    double probe_per_s = 0.1;   // ... beyond the link's last measured throughput
    double probe_s = 5.0;       // ... for this long
    double hold_s = 1.0;        // no rise until the link has kept up this long
    double max_step_s = 0.25;   // the most elapsed time one frame's rise counts
    double memory_s = 10.0;     // the link's remembered throughput: the highest measured this recently
  };

  VideoRateControl() = default;
  explicit VideoRateControl(Params p) : p_(p) {}

  // One frame, at now_ns (any steady clock). ceiling_kbps: the client's or the node's bitrate
  // (kH264MinKbps..kH264MaxKbps); link_kbps: the connection's measured throughput (0: not
  // measured yet); waited: the frame waited for the link. Returns the target for this frame.
  uint32_t update(int64_t now_ns, uint32_t ceiling_kbps, uint32_t link_kbps, bool waited);

  uint32_t target_kbps() const { return uint32_t(target_ + 0.5); }
  // The target lies below the ceiling because of the link.
  bool limited() const { return limited_; }

 private:
  Params p_;
  double target_ = 0;  // kbit/s; 0 before the first frame
  uint32_t ceiling_ = 0;
  bool limited_ = false;
  int64_t last_ns_ = 0;       // the previous frame
  int64_t last_wait_ns_ = 0;  // the last frame that waited for the link
  double link_ = 0;           // the link's remembered throughput (kbit/s; 0: none)
  int64_t link_ns_ = 0;       // when link_ was measured
  int64_t above_ns_ = 0;      // when the target rose beyond link_ (0: it is not beyond)
};

}  // namespace tessera
