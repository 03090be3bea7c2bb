// Bandwidth adaptation of the H.264 display: the control law (codecs/video_rate.h) against a
// simulated link, and the link meter (net/link_meter.h) against a simulated websocketpp queue.
#include <catch2/catch.hpp>

#include <algorithm>
#include <cmath>
#include <deque>

#include "codecs/h264.h"
#include "codecs/video_rate.h"
#include "net/link_meter.h"

using namespace tessera;

namespace {

constexpr int64_t kMs = 1'000'000;

}  // namespace

TEST_CASE("The target starts at the ceiling and stays there while the link keeps up", "[unit][video]") {
  VideoRateControl rc;
  for (int i = 0; i < 100; ++i) CHECK(rc.update(int64_t(i) * 33 * kMs, 8000, 0, false) == 8000);
  CHECK_FALSE(rc.limited());
  // A measured link faster than the ceiling changes nothing either, waiting or not.
  CHECK(rc.update(4000 * kMs, 8000, 50000, true) == 8000);
}

TEST_CASE("A frame that waits for the link cuts the target to 80% of its throughput, within the bounds",
          "[unit][video]") {
  VideoRateControl rc;
  rc.update(0, 8000, 0, false);
  CHECK(rc.update(33 * kMs, 8000, 2000, true) == 1600);
  CHECK(rc.limited());
  // A wait while the target is already below 80% of the link holds it (never raises it).
  CHECK(rc.update(66 * kMs, 8000, 3000, true) == 1600);
  // An unmeasured link (0) gives no cut, but still holds.
  CHECK(rc.update(99 * kMs, 8000, 0, true) == 1600);
  // Never below the protocol's minimum.
  CHECK(rc.update(132 * kMs, 8000, 50, true) == kH264MinKbps);
}

TEST_CASE("The target rises step by step once the link has kept up for a second, slowly beyond the link, up to the ceiling",
          "[unit][video]") {
  VideoRateControl rc;
  rc.update(0, 8000, 0, false);
  REQUIRE(rc.update(10 * kMs, 8000, 1000, true) == 800);
  int64_t t = 10 * kMs;
  // Held for the hold time (1 s) after the last wait.
  while (t < 1000 * kMs) {
    t += 33 * kMs;
    CHECK(rc.update(t, 8000, 0, false) == 800);
  }
  // Then 50% a second, by elapsed time, up to the link's last throughput (1000: in ~0.45 s),
  // then 10% a second beyond it.
  uint32_t prev = 800, at_2s = 0, at_6s = 0;
  while (t < 6050 * kMs) {
    t += 33 * kMs;
    const uint32_t k = rc.update(t, 8000, 0, false);
    CHECK(k >= prev);
    prev = k;
    if (at_2s == 0 && t >= 2010 * kMs) at_2s = k;
    if (at_6s == 0 && t >= 6000 * kMs) at_6s = k;
  }
  CHECK(at_2s > 1000);
  CHECK(at_2s < 1100);
  CHECK(at_6s > 1000 * 1.45);  // 10% a second for 4.5 s: ~1.57x
  CHECK(at_6s < 1000 * 1.7);
  // After 5 s beyond the link without a wait, 50% a second again: at the ceiling within ~4 s
  // more, never above it.
  for (int i = 0; i < 150; ++i) CHECK(rc.update(t += 33 * kMs, 8000, 0, false) <= 8000);
  CHECK(rc.target_kbps() == 8000);
  CHECK_FALSE(rc.limited());
  // A long pause between frames is one step, not a jump.
  rc.update(t += 10 * kMs, 8000, 1000, true);
  REQUIRE(rc.target_kbps() == 800);
  t += 60'000 * kMs;
  CHECK(rc.update(t, 8000, 0, false) <= uint32_t(800 * 1.125 + 1));
}

TEST_CASE("A throughput measured low for a moment does not hold the target low: the link remembers its best of the last 10 s",
          "[unit][video]") {
  VideoRateControl rc;
  rc.update(0, 4000, 0, false);
  int64_t t = 0;
  REQUIRE(rc.update(t += 33 * kMs, 4000, 500, true) == 400);  // the link: 500 kbit/s
  // The receiver stalls for a moment: the link reads 125 kbit/s, and the target is cut to it.
  REQUIRE(rc.update(t += 33 * kMs, 4000, 125, true) == 100);
  // Then the link keeps up: after the hold, 50% a second back up to the 500 it carried 0.07 s
  // before (in ~3.3 s), not 10% a second beyond the 125 of the stall (that would take ~14 s).
  const int64_t stall = t;
  while (t < stall + 4800 * kMs) rc.update(t += 33 * kMs, 4000, 0, false);
  CHECK(rc.target_kbps() >= 500);
  CHECK(rc.target_kbps() < 560);  // and then slowly beyond it
  // A link that really became slower: its higher throughput is forgotten after 10 s, and the
  // target then probes slowly beyond what the link now carries.
  VideoRateControl slow;
  slow.update(0, 4000, 0, false);
  t = 0;
  REQUIRE(slow.update(t += 33 * kMs, 4000, 2000, true) == 1600);
  t += 11'000 * kMs;
  REQUIRE(slow.update(t, 4000, 400, true) == 320);
  const int64_t cut = t;
  while (t < cut + 4800 * kMs) slow.update(t += 33 * kMs, 4000, 0, false);
  CHECK(slow.target_kbps() > 400);
  CHECK(slow.target_kbps() < 600);  // 50% a second to 400, then 10% a second (~3.3 s: ~1.4x)
}

TEST_CASE("The client's ceiling bounds the target, and a new one applies at once unless the link holds it",
          "[unit][video]") {
  VideoRateControl rc;
  CHECK(rc.update(0, 2000, 0, false) == 2000);
  CHECK(rc.update(33 * kMs, 500, 0, false) == 500);      // lowered: at once
  CHECK(rc.update(66 * kMs, 20000, 0, false) == 20000);  // raised, the link not limiting: at once
  CHECK(rc.update(99 * kMs, 20000, 5000, true) == 4000); // the link cuts
  CHECK(rc.update(132 * kMs, 30000, 5000, false) == 4000);  // raised while held: the target stays
  CHECK(rc.update(165 * kMs, 3000, 0, false) == 3000);      // lowered below the target: the ceiling
  CHECK_FALSE(rc.limited());
}

// A link of `kbps` behind a sender that encodes at the target: frames of target/fps bits, a
// frame's write ending once a buffer of `hidden_ms` of the link's time (the kernel's, which the
// node does not see) has room for it; the next frame waits while the write before it has not
// ended; the link is measured only while frames wait. The law must settle near the link's
// throughput, the frames must keep coming, and their latency must stay bounded.
TEST_CASE("Against a simulated link, the target settles near the link's throughput and frames flow",
          "[unit][video]") {
  for (double hidden_ms : {0.0, 1000.0})
    for (double link : {300.0, 1500.0, 6000.0}) {  // kbit/s = bits per ms
      VideoRateControl rc;
      const double render_ms = 20;  // the renderer could give 50 frames/s
      const double cap = hidden_ms * link;
      double t = 0, q = 0, q_t = 0;  // bits in the link (its buffer and in flight) at time q_t
      double write_end = 0, fps = 30, last = 0, sum_target = 0, sum_n = 0, worst_latency = 0;
      int frames = 0, waits = 0;
      uint32_t lo = 1000000, hi = 0;
      auto drain = [&](double at) {
        q = std::max(0.0, q - link * (at - q_t));
        q_t = at;
      };
      while (t < 40000) {
        const double rendered = t;
        const bool waited = write_end > t;
        t = std::max(t, write_end);
        const uint32_t target = rc.update(int64_t(t * kMs), 8000, waited ? uint32_t(link) : 0, waited);
        if (t > last) fps = std::clamp(0.8 * fps + 0.2 * 1000 / (t - last), 1.0, 120.0);  // as the encoder measures it
        last = t;
        const double bits = target * 1000.0 / fps;
        drain(t);
        q += bits;  // the frame, written into the link's buffer as room comes
        write_end = t + std::max(0.0, (q - cap) / link);
        if (t > 20000) worst_latency = std::max(worst_latency, q / link + (t - rendered));
        ++frames;
        waits += waited;
        if (t > 20000) {
          sum_target += target;
          sum_n += 1;
          lo = std::min(lo, target);
          hi = std::max(hi, target);
        }
        t += render_ms;
      }
      INFO("link " << link << " kbit/s, " << hidden_ms << " ms hidden: frames " << frames << ", waits " << waits
                   << ", target " << lo << ".." << hi << ", mean " << sum_target / sum_n << ", worst latency "
                   << worst_latency << " ms");
      CHECK(hi <= 8000);
      if (link < 8000 * 0.8) {
        CHECK(lo >= 0.75 * link - 1);
        CHECK(hi <= link * (hidden_ms > 0 ? 1.6 : 1.1));
        CHECK(sum_target / sum_n >= 0.8 * link);
        CHECK(worst_latency < hidden_ms + 500);  // the buffer, and a frame or two
      }
      CHECK(frames >= 40000 / (render_ms * 1.6));  // the frames keep coming, near the render rate
    }
}

// A connection as the node sees it: websocketpp's write in progress and its queue behind it
// (its buffered amount), which goes into the next write whole when the write ends; the write
// goes into the kernel as the kernel has room (at most `lowat` bytes not yet sent, refilled
// when they fall to half, as TCP_NOTSENT_LOWAT does); the link takes the kernel's bytes at
// `bytes_per_ms` on average, smoothly or (bursty) all at once every 20 ms, as a slow reader
// with a small window makes it; acked counts what it took.
struct FakeConnection {
  double bytes_per_ms;
  bool bursty = false;
  double lowat = 32 << 10;
  double writing = 0;  // bytes of the write in progress not yet in the kernel
  bool write = false;
  size_t queue = 0;    // websocketpp's buffered amount
  double unsent = 0;   // in the kernel
  double acked = 0;
  double credit = 0, t = 0;
  void step(double ms) {
    t += ms;
    if (!bursty) {
      credit = bytes_per_ms * ms;
    } else if (std::fmod(t, 20.0) < ms) {
      credit = bytes_per_ms * 20;  // the window opens
    }
    const double sent = std::min(unsent, credit);
    unsent -= sent;
    acked += sent;
    credit = bursty ? credit - sent : 0;
    if (write && unsent < lowat / 2) {
      const double n = std::min(writing, lowat - unsent);
      writing -= n;
      unsent += n;
    }
    if (write && writing <= 0) write = false;
    if (!write && queue) {
      write = true;
      writing = double(queue);
      queue = 0;
    }
  }
  void send(size_t bytes) { queue += bytes; }
};

TEST_CASE("The link meter measures the throughput of a link that holds the node's frames back", "[unit][video]") {
  for (bool bursty : {false, true})
    for (double kbps : {400.0, 3000.0, 8000.0}) {
      FakeConnection con{kbps / 8, bursty};  // kbit/s = bytes/ms * 8
      LinkMeter meter;
      std::deque<size_t> waiting;  // frames the node holds (c.out)
      int samples = 0;
      size_t frame = 6000;
      double t = 0;
      // Frames come faster than the link carries them (every 6 ms, two sizes; the newest
      // replaces a waiting one), a frame is handed over only while websocketpp's queue is
      // empty, and the node looks every 2 ms.
      for (int step = 0; step < 40000; ++step) {
        t += 0.1;
        con.step(0.1);
        if (step % 60 == 0) {
          if (!waiting.empty()) waiting.pop_back();
          waiting.push_back(frame);
          frame = frame == 6000 ? 9000 : 6000;
        }
        if (step % 20 == 0) {
          while (!waiting.empty() && con.queue == 0) {
            con.send(waiting.front());
            waiting.pop_front();
          }
          samples += meter.look(int64_t(t * kMs), uint64_t(con.acked), uint32_t(con.unsent));
        }
      }
      const uint32_t got = meter.kbps(int64_t(t * kMs));
      INFO("link " << kbps << " kbit/s" << (bursty ? ", bursty" : "") << ", measured " << got << " from " << samples
                   << " samples");
      CHECK(samples > 10);
      CHECK(meter.saturated(int64_t(t * kMs)));
      CHECK(got >= 0.9 * kbps);
      CHECK(got <= 1.1 * kbps);
      // Two seconds without a sample: unknown again.
      CHECK(meter.kbps(int64_t((t + 2100) * kMs)) == 0);
    }
}

TEST_CASE("The link meter takes no sample from a link that keeps up", "[unit][video]") {
  FakeConnection con{100000.0 / 8};  // 100 Mbit/s
  LinkMeter meter;
  double t = 0;
  int samples = 0;
  for (int step = 0; step < 20000; ++step) {
    t += 0.1;
    con.step(0.1);
    if (step % 20 == 0) {
      if (step % 320 == 0) con.send(10000);  // a 10 KB frame every 32 ms: carried in 0.8 ms
      samples += meter.look(int64_t(t * kMs), uint64_t(con.acked), uint32_t(con.unsent));
    }
  }
  CHECK(samples == 0);
  CHECK(meter.kbps(int64_t(t * kMs)) == 0);
  CHECK_FALSE(meter.saturated(int64_t(t * kMs)));
}
