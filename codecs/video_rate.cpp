// The H.264 display's bandwidth adaptation (codecs/video_rate.h).
#include "codecs/video_rate.h"

#include <algorithm>

#include "codecs/h264.h"

namespace tessera {

uint32_t VideoRateControl::update(int64_t now_ns, uint32_t ceiling_kbps, uint32_t link_kbps, bool waited) {
  const double ceiling = std::clamp(ceiling_kbps, kH264MinKbps, kH264MaxKbps);
  const double floor = kH264MinKbps;
  // A new ceiling (the first frame, or the client's video record).
  if (target_ == 0 || ceiling_kbps != ceiling_) {
    target_ = limited_ ? std::min(target_, ceiling) : ceiling;
    ceiling_ = ceiling_kbps;
  }
  const double dt = last_ns_ ? double(now_ns - last_ns_) / 1e9 : 0;
  last_ns_ = now_ns;
  if (waited) {
    // The link bounds the frame rate: fit the stream to what it carries.
    last_wait_ns_ = now_ns;
    if (link_kbps > 0) {
      const double link = double(link_kbps);
      if (target_ > p_.fit * link) target_ = std::max(floor, p_.fit * link);
      // Remembered: the highest throughput of the last memory_s (a new one once that has passed).
      if (link >= link_ || double(now_ns - link_ns_) / 1e9 > p_.memory_s) {
        link_ = link;
        link_ns_ = now_ns;
      }
      if (target_ < link_) above_ns_ = 0;
    }
  } else if (target_ < ceiling && double(now_ns - last_wait_ns_) / 1e9 >= p_.hold_s && dt > 0) {
    // The link keeps up: rise, by elapsed time (so the law does not depend on the frame rate);
    // slowly for a while beyond the throughput the link last had.
    double rate = p_.growth_per_s;
    if (link_ > 0 && target_ >= link_) {
      if (above_ns_ == 0) above_ns_ = now_ns;
      if (double(now_ns - above_ns_) / 1e9 < p_.probe_s) rate = p_.probe_per_s;
    }
    target_ = std::min(ceiling, target_ * (1 + rate * std::min(dt, p_.max_step_s)));
  }
  target_ = std::clamp(target_, floor, ceiling);
  limited_ = target_ < ceiling;
  return target_kbps();
}

}  // namespace tessera
