// net/link_model.h: one direction of `tessera linkem`'s emulated link (rate, queue, delay, loss).
#include <catch2/catch.hpp>

#include <vector>

#include "net/link_model.h"

using namespace tessera;

namespace {
constexpr int64_t kMs = 1'000'000, kUs = 1'000;
}

TEST_CASE("Without a rate limit a packet arrives after the delay alone", "[link]") {
  LinkParams p;
  p.delay_ms = 25;
  LinkDirection d(p);
  CHECK(d.admit(0, 1500) == 25 * kMs);
  CHECK(d.admit(3 * kMs, 60) == 28 * kMs);
  CHECK(d.admit(3 * kMs, 1500) == 28 * kMs);  // no queue: side by side
  CHECK(d.forwarded() == 3);
  CHECK(d.bytes() == 3060);
}

TEST_CASE("A rated link sends one packet at a time, in order, then delays each", "[link]") {
  LinkParams p;
  p.mbit_s = 8;  // one byte a microsecond
  p.delay_ms = 5;
  p.queue_bytes = 1 << 20;
  LinkDirection d(p);
  // A burst of ten 1000-byte packets at t = 0 leaves 1 ms apart.
  for (int k = 0; k < 10; ++k) CHECK(d.admit(0, 1000) == (k + 1) * 1000 * kUs + 5 * kMs);
  // A packet after the link has gone idle starts at once.
  CHECK(d.admit(50 * kMs, 500) == 50 * kMs + 500 * kUs + 5 * kMs);
  // One that comes while the link is busy waits for the packet ahead.
  CHECK(d.admit(50 * kMs + 100 * kUs, 500) == 50 * kMs + 1000 * kUs + 5 * kMs);
}

TEST_CASE("A full queue drops what does not fit, and takes packets again once it drains", "[link]") {
  LinkParams p;
  p.mbit_s = 8;
  p.queue_bytes = 5000;
  LinkDirection d(p);
  int admitted = 0;
  for (int k = 0; k < 10; ++k) admitted += d.admit(0, 1000) != LinkDirection::kDropped;
  CHECK(admitted == 5);  // 0, 1000, ... 4000 bytes waiting before each: the sixth would make 6000
  CHECK(d.full() == 5);
  CHECK(d.lost() == 0);
  // 2 ms later two packets have been sent: room for two more, not three.
  CHECK(d.admit(2 * kMs, 1000) != LinkDirection::kDropped);
  CHECK(d.admit(2 * kMs, 1000) != LinkDirection::kDropped);
  CHECK(d.admit(2 * kMs, 1000) == LinkDirection::kDropped);
  // Once the queue is empty a packet as large as the queue still fits.
  CHECK(d.admit(100 * kMs, 5000) == 105 * kMs);
}

TEST_CASE("The default queue holds 200 ms of the rate, and at least 64 KiB", "[link]") {
  LinkParams p;
  p.mbit_s = 20;
  CHECK(LinkDirection(p).queue_bytes() == 500000);
  p.mbit_s = 1;
  CHECK(LinkDirection(p).queue_bytes() == 64u << 10);
}

TEST_CASE("Loss draws are independent, at the asked rate, and repeatable from the seed", "[link]") {
  auto losses = [](double loss, uint64_t seed, int n, std::vector<bool>* pattern = nullptr) {
    LinkParams p;
    p.loss = loss;
    p.seed = seed;
    LinkDirection d(p);
    for (int i = 0; i < n; ++i) {
      const bool dropped = d.admit(i * kUs, 100) == LinkDirection::kDropped;
      if (pattern) pattern->push_back(dropped);
    }
    CHECK(d.lost() + d.forwarded() == uint64_t(n));
    CHECK(d.full() == 0);
    return d.lost();
  };
  CHECK(losses(0, 1, 10000) == 0);
  CHECK(losses(1, 1, 1000) == 1000);
  // 1% of 100,000: binomial, standard deviation 31.5; 5 of them either side.
  const uint64_t lost = losses(0.01, 7, 100000);
  CHECK(lost > 1000 - 158);
  CHECK(lost < 1000 + 158);
  // Lost packets do not come in runs more than chance makes: pairs of consecutive losses
  // about loss^2 of the packets (10% loss: 1% of pairs, 1000 of 100,000; 5 sd is 158).
  std::vector<bool> pat;
  losses(0.1, 3, 100000, &pat);
  int pairs = 0;
  for (size_t i = 1; i < pat.size(); ++i) pairs += pat[i] && pat[i - 1];
  CHECK(pairs > 1000 - 158);
  CHECK(pairs < 1000 + 158);
  std::vector<bool> a, b, c;
  losses(0.1, 11, 1000, &a);
  losses(0.1, 11, 1000, &b);
  losses(0.1, 12, 1000, &c);
  CHECK(a == b);
  CHECK(a != c);
}

TEST_CASE("Link parameters no link has are refused", "[link]") {
  auto bad = [](double mbit, double delay, double loss) {
    LinkParams p;
    p.mbit_s = mbit;
    p.delay_ms = delay;
    p.loss = loss;
    CHECK_THROWS_AS(LinkDirection(p), std::invalid_argument);
  };
  bad(-1, 0, 0);
  bad(0, -5, 0);
  bad(0, 0, 1.5);
  bad(0, 0, -0.1);
  bad(std::nan(""), 0, 0);
  bad(0, std::nan(""), 0);
  bad(1e9, 0, 0);
}
