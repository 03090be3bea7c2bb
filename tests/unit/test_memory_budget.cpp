// The node-wide memory budget (protocol/memory_budget.h): thread-safe accounting, per-holder
// shares, and the payload sizes a client message declares before it is decoded.
#include <catch2/catch.hpp>

#include <thread>
#include <vector>

#include "protocol/memory_budget.h"
#include "protocol/protocol.h"

using namespace tessera;
using namespace tessera::protocol;

TEST_CASE("A memory budget refuses what would cross its limit and counts what is forced", "[unit]") {
  MemoryBudget b(1000);
  CHECK(b.try_acquire(600));
  CHECK_FALSE(b.try_acquire(401));  // 1001 > 1000: nothing taken
  CHECK(b.used() == 600);
  CHECK(b.try_acquire(400));        // exactly the limit
  CHECK_FALSE(b.try_acquire(1));
  b.acquire(50);                    // forced (a queued frame): may go beyond
  CHECK(b.used() == 1050);
  CHECK(b.peak() == 1050);
  b.release(1050);
  CHECK(b.used() == 0);
  b.release(10);                    // never below zero
  CHECK(b.used() == 0);
  CHECK_FALSE(b.try_acquire(UINT64_MAX));
  CHECK(MemoryBudget::default_limit() >= (64u << 20));
}

TEST_CASE("Budget shares take, settle and give back their bytes", "[unit]") {
  auto b = std::make_shared<MemoryBudget>(1000);
  {
    BudgetShare a(b), c(b);
    CHECK(a.reserve(700));
    CHECK_FALSE(c.reserve(400));  // another holder is refused, a keeps its bytes
    CHECK(c.held() == 0);
    CHECK(c.reserve(300));
    a.set(200);                   // a settles to what it holds: 500 come back
    CHECK(b->used() == 500);
    CHECK(c.reserve(500));
    a.set(900);                   // forced
    CHECK(b->used() == 1700);
  }
  CHECK(b->used() == 0);          // returned when the holders end
  BudgetShare none;               // no budget: unlimited, nothing counted
  CHECK(none.reserve(UINT64_MAX));
  none.set(5);
  CHECK(none.held() == 0);
  BudgetShare later;
  later.attach(b);
  CHECK(later.reserve(10));
  CHECK(b->used() == 10);
}

TEST_CASE("A memory budget is exact under concurrent holders", "[unit]") {
  auto b = std::make_shared<MemoryBudget>(100000);
  std::vector<std::thread> threads;
  std::atomic<int> refused{0};
  for (int t = 0; t < 8; ++t)
    threads.emplace_back([&] {
      for (int i = 0; i < 20000; ++i) {
        if (b->try_acquire(7)) {
          b->release(7);
        } else {
          ++refused;
        }
        BudgetShare s(b);
        s.set(3);
      }
    });
  for (auto& t : threads) t.join();
  CHECK(b->used() == 0);
  CHECK(b->peak() <= 100000);
  CHECK(refused == 0);
}

namespace {

SetBuffer floats(Id id, size_t n, bool deflate = false) {
  SetBuffer b;
  b.id = id;
  b.buffer.type = Buffer::Type::f32;
  b.buffer.components = 1;
  b.buffer.f.assign(n, 0.25f);
  b.deflate = deflate;
  return b;
}

}  // namespace

TEST_CASE("The payloads a message declares are read from its headers, deflated or not", "[unit]") {
  Limits lim;
  SetTexture tex;
  tex.id = 5;
  tex.texture.width = 3;
  tex.texture.height = 2;
  tex.texture.rgba.assign(3 * 2 * 4, 7);
  auto msg = encode(std::vector<ClientRecord>{SetCamera{}, floats(1, 1000, true), tex, Remove{RecordType::buffer, 1},
                                              RenderRequest{3}});
  auto d = declared_payloads(msg.data(), msg.size(), lim);
  REQUIRE(d);
  REQUIRE(d->size() == 5);
  CHECK((*d)[0].bytes == 0);
  CHECK((*d)[1].bytes == 4000);  // inflated size, though a few bytes on the wire
  CHECK((*d)[1].size < 200);
  CHECK((*d)[2].bytes == 24);
  CHECK((*d)[3].bytes == 0);
  CHECK((*d)[4].bytes == 0);
  // Beyond the per-record limits: the decoder refuses it before it allocates, nothing counted.
  lim.max_buffer_bytes = 3999;
  CHECK((*declared_payloads(msg.data(), msg.size(), lim))[1].bytes == 0);
  // Cutting records out keeps the others decodable, in order.
  auto cut = without_records(msg.data(), msg.size(), *d, {1, 3});
  auto recs = decode_client(cut.data(), cut.size(), Limits{});
  REQUIRE(recs);
  REQUIRE(recs.value().size() == 3);
  CHECK(std::holds_alternative<SetCamera>(recs.value()[0]));
  CHECK(std::holds_alternative<SetTexture>(recs.value()[1]));
  CHECK(std::holds_alternative<RenderRequest>(recs.value()[2]));
  // Bad framing: nothing is declared (the decoder reports it).
  for (auto bad : {std::vector<uint8_t>{1, 2, 3}, std::vector<uint8_t>(msg.begin(), msg.end() - 1)})
    CHECK_FALSE(declared_payloads(bad.data(), bad.size(), Limits{}));
  auto wrong_count = msg;
  wrong_count[4] = 200;
  CHECK_FALSE(declared_payloads(wrong_count.data(), wrong_count.size(), Limits{}));
}
