#pragma once
// How fast a WebSocket connection's link carries what the node sends (docs/protocol.md,
// "Bandwidth adaptation"), measured while the link is what holds the node's bytes back. Pure
// code: the network thread feeds it (net/server.cpp), tests feed it by hand
// (tests/unit/test_video_rate.cpp).
//
// The kernel counts the bytes the peer has acknowledged and knows the bytes written and not yet
// sent (TCP_INFO, net/tcp_stats.h). While bytes wait to be sent, the link is busy, and the
// growth of the acknowledged count is its throughput. At each look at the connection (every
// 2 ms while the kernel or the node holds bytes back, net/server.cpp), the stretch since the
// last look is busy when both looks found bytes waiting in the kernel. Stretches are added up
// in windows of 250 ms: a window busy for at least half its time is *saturated* (the link, not
// the node, sets the pace) and gives a sample, its acknowledged bytes over its busy time.
// Busy stretches in which the link stalls (a receiver that reads slowly closes its window)
// count as well as bursts, so a bursty link is measured at its mean. The kernel's waiting bytes
// are kept few (TCP_NOTSENT_LOWAT, net/server.cpp), so they mean the link is behind by a
// fraction of a second at most. A link that keeps up is never measured, and needs not be.
#include <cstddef>
#include <cstdint>

namespace tessera {

class LinkMeter {
 public:
  static constexpr double kWeight = 0.3;              // of a new sample in the smoothed rate
  static constexpr double kWindowS = 0.25;            // the windows of looks
  static constexpr double kSaturated = 0.5;           // the busy share of a saturated window
  static constexpr int64_t kStaleNs = 2'000'000'000;  // samples older than this are forgotten
  static constexpr int64_t kSaturatedNs = 500'000'000;  // saturated(): a saturated window this recent

  // One look at the connection at now_ns: the kernel's count of acknowledged bytes and its
  // bytes not yet sent. Returns true when a saturated window ended (and gave a sample).
  bool look(int64_t now_ns, uint64_t acked, uint32_t notsent) {
    bool sampled = false;
    if (last_ns_ > 0 && now_ns > last_ns_) {
      const double dt = double(now_ns - last_ns_) / 1e9;
      window_s_ += dt;
      if (last_notsent_ > 0 && notsent > 0 && acked >= last_acked_) {
        busy_s_ += dt;
        busy_bytes_ += double(acked - last_acked_);
      }
      if (window_s_ >= kWindowS) {
        if (busy_s_ >= kSaturated * window_s_) {
          sample(now_ns, busy_bytes_, busy_s_);
          saturated_ns_ = now_ns;
          sampled = true;
        }
        window_s_ = busy_s_ = busy_bytes_ = 0;
      }
    }
    last_ns_ = now_ns;
    last_acked_ = acked;
    last_notsent_ = notsent;
    return sampled;
  }
  // The last look found bytes waiting in the kernel: the next should come soon.
  bool watching() const { return last_notsent_ > 0; }
  // A window that ended within the last kSaturatedNs was saturated.
  bool saturated(int64_t now_ns) const { return saturated_ns_ > 0 && now_ns - saturated_ns_ <= kSaturatedNs; }
  int64_t saturated_ns() const { return saturated_ns_; }

  // The smoothed throughput in kbit/s; 0 before the first sample and once the last is stale.
  uint32_t kbps(int64_t now_ns) const {
    if (last_sample_ns_ == 0 || now_ns - last_sample_ns_ > kStaleNs || secs_ <= 0) return 0;
    const double k = bytes_ * 8 / secs_ / 1000;
    return k < 1 ? 1 : (k > 4e9 ? 4000000000u : uint32_t(k));
  }

 private:
  void sample(int64_t now_ns, double bytes, double secs) {
    if (now_ns - last_sample_ns_ > kStaleNs) bytes_ = secs_ = 0;  // a new episode: start afresh
    // Decayed sums of bytes and of seconds.
    bytes_ = (1 - kWeight) * bytes_ + kWeight * bytes;
    secs_ = (1 - kWeight) * secs_ + kWeight * secs;
    last_sample_ns_ = now_ns;
  }

  int64_t last_ns_ = 0;  // the last look
  uint64_t last_acked_ = 0;
  uint32_t last_notsent_ = 0;
  double window_s_ = 0, busy_s_ = 0, busy_bytes_ = 0;  // the window so far
  int64_t saturated_ns_ = 0;  // the end of the last saturated window
  double bytes_ = 0, secs_ = 0;
  int64_t last_sample_ns_ = 0;
};

}  // namespace tessera
