#include "protocol/memory_budget.h"

#include <unistd.h>

#include <algorithm>
#include <cstring>

namespace tessera {

bool MemoryBudget::try_acquire(uint64_t bytes) {
  uint64_t cur = used_.load(std::memory_order_relaxed);
  do {
    if (bytes > limit_ || cur > limit_ - bytes) return false;
  } while (!used_.compare_exchange_weak(cur, cur + bytes, std::memory_order_relaxed));
  note_peak(cur + bytes);
  return true;
}

void MemoryBudget::acquire(uint64_t bytes) { note_peak(used_.fetch_add(bytes, std::memory_order_relaxed) + bytes); }

void MemoryBudget::release(uint64_t bytes) {
  uint64_t cur = used_.load(std::memory_order_relaxed);
  // Never below zero, even if a holder gives back more than it took (a bug, not a wrap-around).
  while (!used_.compare_exchange_weak(cur, cur - std::min(cur, bytes), std::memory_order_relaxed)) {
  }
}

void MemoryBudget::note_peak(uint64_t now) {
  uint64_t p = peak_.load(std::memory_order_relaxed);
  while (now > p && !peak_.compare_exchange_weak(p, now, std::memory_order_relaxed)) {
  }
}

uint64_t MemoryBudget::default_limit() {
  const long pages = sysconf(_SC_PHYS_PAGES), page = sysconf(_SC_PAGE_SIZE);
  if (pages <= 0 || page <= 0) return 1ull << 30;
  return uint64_t(pages) * uint64_t(page) / 2;
}

bool BudgetShare::reserve(uint64_t bytes) {
  if (!budget_) return true;
  if (bytes == 0) return true;
  if (!budget_->try_acquire(bytes)) return false;
  held_ += bytes;
  return true;
}

void BudgetShare::set(uint64_t bytes) {
  if (!budget_) return;
  if (bytes > held_) budget_->acquire(bytes - held_);
  else if (bytes < held_) budget_->release(held_ - bytes);
  held_ = bytes;
}

namespace {

uint32_t u32_at(const uint8_t* p) {
  uint32_t v;
  std::memcpy(&v, p, 4);
  return v;
}

}  // namespace

std::optional<std::vector<DeclaredRecord>> declared_payloads(const uint8_t* data, size_t size,
                                                            const protocol::Limits& limits) {
  using namespace protocol;
  if (size < kMessageHeaderSize || size > limits.max_message_bytes) return std::nullopt;
  if (data[0] != kMagic0 || data[1] != kMagic1 || data[2] != kVersion || data[3] != uint8_t(Channel::client))
    return std::nullopt;
  const uint32_t count = u32_at(data + 4);
  if (count == 0 || count > limits.max_records || count > (size - kMessageHeaderSize) / kRecordHeaderSize)
    return std::nullopt;
  std::vector<DeclaredRecord> out;
  out.reserve(count);
  size_t at = kMessageHeaderSize;
  for (uint32_t i = 0; i < count; ++i) {
    if (size - at < kRecordHeaderSize) return std::nullopt;
    const uint8_t type = data[at], op = data[at + 1];
    const uint32_t len = u32_at(data + at + 4);
    if (len > size - at - kRecordHeaderSize) return std::nullopt;
    const uint8_t* body = data + at + kRecordHeaderSize;
    DeclaredRecord d;
    d.index = i;
    d.offset = at;
    d.size = kRecordHeaderSize + len;
    if (op == uint8_t(Op::set) && type == uint8_t(RecordType::buffer) && len >= 12) {
      const uint64_t bytes = uint64_t(u32_at(body + 8)) * 4;  // values, f32 or u32 each
      if (bytes <= limits.max_buffer_bytes) d.bytes = bytes;
    } else if (op == uint8_t(Op::set) && type == uint8_t(RecordType::texture) && len >= 20) {
      const uint32_t w = u32_at(body + 12), h = u32_at(body + 16);
      const uint32_t max = uint32_t(std::max(0, limits.max_texture_size));
      if (w > 0 && h > 0 && w <= max && h <= max) d.bytes = uint64_t(w) * h * 4;  // decoded RGBA8
    }
    out.push_back(d);
    at += d.size;
  }
  if (at != size) return std::nullopt;
  return out;
}

std::vector<uint8_t> without_records(const uint8_t* data, size_t size, const std::vector<DeclaredRecord>& records,
                                     const std::vector<uint32_t>& drop) {
  std::vector<uint8_t> out;
  out.reserve(size);
  out.insert(out.end(), data, data + protocol::kMessageHeaderSize);
  uint32_t kept = 0;
  size_t d = 0;
  for (const auto& r : records) {
    while (d < drop.size() && drop[d] < r.index) ++d;
    if (d < drop.size() && drop[d] == r.index) continue;
    out.insert(out.end(), data + r.offset, data + r.offset + r.size);
    ++kept;
  }
  std::memcpy(out.data() + 4, &kept, 4);
  return out;
}

}  // namespace tessera
