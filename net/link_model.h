#pragma once
// One direction of an emulated network link (`tessera linkem`, app/cmd_linkem.cpp): what
// happens to each IP packet that enters it. Pure code, fed with times by the forwarder and by
// tests (tests/unit/test_link_model.cpp).
//
// The model is a router's drop-tail queue in front of a link of fixed rate, followed by a fixed
// propagation delay, with random loss on the way in (the way sch_netem composes `rate`, `delay`,
// `loss` and `limit`):
// - a packet is lost with probability `loss`, independently of the others (Bernoulli; seeded, so
//   a run can be repeated);
// - otherwise it joins the queue unless the bytes still waiting to be sent, plus its own, exceed
//   `queue_bytes` (then it is dropped: the queue is full);
// - the link sends one packet at a time at `mbit_s`, so a packet leaves the queue once every
//   packet ahead of it and itself have been sent;
// - it arrives `delay_ms` after it has been sent.
// Arrival times are therefore in the order the packets came in, and a forwarder can keep each
// direction's packets in one FIFO.
#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <random>
#include <stdexcept>
#include <string>

namespace tessera {

struct LinkParams {
  double mbit_s = 0;         // the link's rate; 0: no rate limit (then there is no queue either)
  double delay_ms = 0;       // one way, after the packet has been sent
  double loss = 0;           // probability of losing a packet, 0..1
  size_t queue_bytes = 0;    // the queue's size; 0: what the link sends in kDefaultQueueMs
  uint64_t seed = 1;         // of the loss draws

  static constexpr double kDefaultQueueMs = 200;     // like tbf's `latency 200ms`
  static constexpr size_t kMinQueueBytes = 64 << 10;  // a few dozen full-size packets at least

  // Throws std::invalid_argument for values no link has.
  void validate() const {
    if (!(mbit_s >= 0 && mbit_s <= 100000)) throw std::invalid_argument("rate must be 0..100000 Mbit/s");
    if (!(delay_ms >= 0 && delay_ms <= 10000)) throw std::invalid_argument("delay must be 0..10000 ms");
    if (!(loss >= 0 && loss <= 1)) throw std::invalid_argument("loss must be 0..1");
  }
  size_t effective_queue_bytes() const {
    if (queue_bytes) return queue_bytes;
    return std::max(kMinQueueBytes, size_t(mbit_s * 1e6 / 8 * kDefaultQueueMs / 1e3));
  }
};

class LinkDirection {
 public:
  static constexpr int64_t kDropped = -1;

  explicit LinkDirection(const LinkParams& p)
      : p_(validated(p)), queue_bytes_(p.effective_queue_bytes()), delay_ns_(int64_t(std::llround(p.delay_ms * 1e6))),
        rng_(p.seed) {}

  // A packet of `bytes` enters at now_ns (a monotonic clock). Returns when it arrives at the
  // other end, or kDropped when it is lost or the queue is full.
  int64_t admit(int64_t now_ns, size_t bytes) {
    ++packets_;
    if (p_.loss > 0 && unit_(rng_) < p_.loss) {
      ++lost_;
      return kDropped;
    }
    int64_t sent_ns = now_ns;
    if (p_.mbit_s > 0) {
      const int64_t start = std::max(now_ns, busy_until_ns_);
      // Bytes still waiting to be sent (the one on the wire counted whole, as tbf and netem do).
      const double waiting = double(start - now_ns) * p_.mbit_s / 8e3;
      if (waiting + double(bytes) > double(queue_bytes_)) {
        ++full_;
        return kDropped;
      }
      busy_until_ns_ = start + int64_t(std::llround(double(bytes) * 8e3 / p_.mbit_s));
      sent_ns = busy_until_ns_;
    }
    ++forwarded_;
    bytes_ += bytes;
    return sent_ns + delay_ns_;
  }

  uint64_t packets() const { return packets_; }    // entered
  uint64_t lost() const { return lost_; }          // by the loss draw
  uint64_t full() const { return full_; }          // dropped at a full queue
  uint64_t forwarded() const { return forwarded_; }
  uint64_t bytes() const { return bytes_; }        // forwarded
  size_t queue_bytes() const { return queue_bytes_; }

 private:
  static const LinkParams& validated(const LinkParams& p) {
    p.validate();
    return p;
  }

  LinkParams p_;
  size_t queue_bytes_;
  int64_t delay_ns_;
  int64_t busy_until_ns_ = 0;  // when the link has sent every packet admitted so far
  std::mt19937_64 rng_;
  std::uniform_real_distribution<double> unit_{0.0, 1.0};
  uint64_t packets_ = 0, lost_ = 0, full_ = 0, forwarded_ = 0, bytes_ = 0;
};

}  // namespace tessera
