#pragma once
// The node-wide memory budget shared by every client of a node (docs/operations.md, "Resource
// bounds"): the buffers and textures of every session's scene (with the updates cached while a
// frame renders and the payloads of a message being decoded) plus the frames queued for slow
// clients. A scene update that would cross it is refused with limit_exceeded; queued frames
// are always counted (they are bounded per client) but never refused.
//
// Pure code (no actors, no sockets): MemoryBudget is thread-safe; a BudgetShare is one holder's
// part of it (a session, a connection) and is used by one thread at a time.
#include <atomic>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <optional>
#include <vector>

#include "protocol/protocol.h"

namespace tessera {

class MemoryBudget {
 public:
  explicit MemoryBudget(uint64_t limit) : limit_(limit) {}
  MemoryBudget(const MemoryBudget&) = delete;
  MemoryBudget& operator=(const MemoryBudget&) = delete;

  uint64_t limit() const { return limit_; }
  uint64_t used() const { return used_.load(std::memory_order_relaxed); }
  uint64_t peak() const { return peak_.load(std::memory_order_relaxed); }
  // Takes `bytes` if the total stays within the limit; false (and nothing taken) otherwise.
  bool try_acquire(uint64_t bytes);
  // Takes `bytes` whatever the total (what is already held: frames produced, a smaller
  // replacement of what was reserved).
  void acquire(uint64_t bytes);
  void release(uint64_t bytes);

  // Half of the physical memory (sysconf), or 1 GiB when it cannot be read.
  static uint64_t default_limit();

 private:
  void note_peak(uint64_t now);
  const uint64_t limit_;
  std::atomic<uint64_t> used_{0}, peak_{0};
};

// One holder's bytes in a budget (none: unlimited, nothing counted). Gives them back when it
// is destroyed.
class BudgetShare {
 public:
  explicit BudgetShare(std::shared_ptr<MemoryBudget> budget = nullptr) : budget_(std::move(budget)) {}
  ~BudgetShare() { set(0); }
  BudgetShare(const BudgetShare&) = delete;
  BudgetShare& operator=(const BudgetShare&) = delete;

  // Names the budget of a share that holds nothing yet (a default-constructed member).
  void attach(std::shared_ptr<MemoryBudget> budget) {
    set(0);
    budget_ = std::move(budget);
  }
  // Takes `bytes` more if the budget has room; false otherwise (always true without a budget).
  bool reserve(uint64_t bytes);
  // Holds exactly `bytes` from now on: takes or gives back the difference (never refused).
  void set(uint64_t bytes);
  uint64_t held() const { return held_; }
  const MemoryBudget* budget() const { return budget_.get(); }

 private:
  std::shared_ptr<MemoryBudget> budget_;
  uint64_t held_ = 0;
};

// The buffer and texture payloads a client message declares, read from its framing and
// record headers before anything is inflated or decoded (a deflated buffer's header gives its
// inflated size). Only `set` records of buffers and textures within the per-record limits
// count: the decoder refuses the others before it allocates. nullopt when the framing is not
// valid (the decoder then reports why).
struct DeclaredRecord {
  uint32_t index = 0;   // in the message
  size_t offset = 0;    // of the record header
  size_t size = 0;      // header + body
  uint64_t bytes = 0;   // declared payload (0: none)
};
std::optional<std::vector<DeclaredRecord>> declared_payloads(const uint8_t* data, size_t size,
                                                            const protocol::Limits& limits);

// The message without the records whose index is in `drop` (ascending); the record count in
// the header is adjusted. `records` is what declared_payloads returned for it.
std::vector<uint8_t> without_records(const uint8_t* data, size_t size, const std::vector<DeclaredRecord>& records,
                                     const std::vector<uint32_t>& drop);

}  // namespace tessera
