#include "lb/sat.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <sstream>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

namespace tessera {
namespace {

constexpr uint8_t kMagic[4] = {'T', 'S', 'A', 'T'};
constexpr uint16_t kVersion = 1;
constexpr int32_t kMaxCoord = 1 << 24;          // packets per axis; 4x4 packets: 67M pixels
constexpr uint64_t kMaxEntries = uint64_t(1) << 31;
constexpr int64_t kParallelMinPackets = 16384;  // below this one sequential pass is faster

void put_u16(uint8_t* p, uint16_t v) {
  p[0] = uint8_t(v);
  p[1] = uint8_t(v >> 8);
}
void put_u32(uint8_t* p, uint32_t v) {
  for (int i = 0; i < 4; ++i) p[i] = uint8_t(v >> (8 * i));
}
void put_u64(uint8_t* p, uint64_t v) {
  for (int i = 0; i < 8; ++i) p[i] = uint8_t(v >> (8 * i));
}
uint16_t get_u16(const uint8_t* p) { return uint16_t(p[0] | (p[1] << 8)); }
uint32_t get_u32(const uint8_t* p) {
  uint32_t v = 0;
  for (int i = 3; i >= 0; --i) v = (v << 8) | p[i];
  return v;
}
uint64_t get_u64(const uint8_t* p) {
#if defined(__BYTE_ORDER__) && __BYTE_ORDER__ == __ORDER_LITTLE_ENDIAN__
  uint64_t v;
  std::memcpy(&v, p, 8);
  return v;
#else
  uint64_t v = 0;
  for (int i = 7; i >= 0; --i) v = (v << 8) | p[i];
  return v;
#endif
}

void check_cost_map(const CostMap& map) {
  const Rect& r = map.packets;
  if (r.x0 < 0 || r.y0 < 0 || r.x1 < r.x0 || r.y1 < r.y0 || r.x1 > kMaxCoord || r.y1 > kMaxCoord) {
    std::ostringstream os;
    os << "Sat::from_cost_map: invalid packet rectangle [" << r.x0 << "," << r.x1 << ")x[" << r.y0 << ","
       << r.y1 << ")";
    throw std::invalid_argument(os.str());
  }
  if (map.cost.size() != size_t(r.area())) {
    std::ostringstream os;
    os << "Sat::from_cost_map: cost map has " << map.cost.size() << " entries, its rectangle "
       << r.width() << "x" << r.height() << " needs " << r.area();
    throw std::invalid_argument(os.str());
  }
}

}  // namespace

Sat::Sat(Rect packets) : packets_(packets), stride_(size_t(packets.width()) + 1) {
  const size_t rows = size_t(packets.height()) + 1;
  table_.reset(new uint64_t[stride_ * rows]);  // uninitialised on purpose: every entry is written
  std::fill(table_.get(), table_.get() + stride_, uint64_t(0));
  for (size_t y = 1; y < rows; ++y) table_[y * stride_] = 0;
}

Sat::Sat(const Sat& o) : packets_(o.packets_), stride_(o.stride_) {
  if (o.table_) {
    const size_t n = stride_ * (size_t(packets_.height()) + 1);
    table_.reset(new uint64_t[n]);
    std::memcpy(table_.get(), o.table_.get(), n * sizeof(uint64_t));
  }
}

Sat& Sat::operator=(const Sat& o) {
  if (this != &o) *this = Sat(o);
  return *this;
}

Sat Sat::from_cost_map_serial(const CostMap& map) {
  check_cost_map(map);
  Sat s(map.packets);
  const int32_t w = map.packets.width(), h = map.packets.height();
  const uint32_t* c = map.cost.data();
  uint64_t* t = s.table_.get();
  const size_t st = s.stride_;
  // One pass: entry = running row sum + the entry above.
  for (int32_t y = 0; y < h; ++y) {
    const uint64_t* above = t + size_t(y) * st + 1;
    uint64_t* row = t + size_t(y + 1) * st + 1;
    const uint32_t* src = c + size_t(y) * size_t(w);
    uint64_t run = 0;
    for (int32_t x = 0; x < w; ++x) {
      run += src[x];
      row[x] = above[x] + run;
    }
  }
  return s;
}

Sat Sat::from_cost_map(const CostMap& map) {
  if (tbb::this_task_arena::max_concurrency() <= 1 || map.packets.area() < kParallelMinPackets)
    return from_cost_map_serial(map);
  check_cost_map(map);
  Sat s(map.packets);
  const int32_t w = map.packets.width(), h = map.packets.height();
  const uint32_t* c = map.cost.data();
  uint64_t* t = s.table_.get();
  const size_t st = s.stride_;
  // Row prefix sums, in parallel over rows.
  tbb::parallel_for(tbb::blocked_range<int32_t>(0, h, 16), [&](const tbb::blocked_range<int32_t>& rows) {
    for (int32_t y = rows.begin(); y < rows.end(); ++y) {
      uint64_t* row = t + size_t(y + 1) * st + 1;
      const uint32_t* src = c + size_t(y) * size_t(w);
      uint64_t run = 0;
      for (int32_t x = 0; x < w; ++x) row[x] = run += src[x];
    }
  });
  // Column sums, in parallel over blocks of columns (each block walks down the rows, so
  // it reads and writes contiguous runs of its row segment).
  tbb::parallel_for(tbb::blocked_range<int32_t>(1, w + 1, 128), [&](const tbb::blocked_range<int32_t>& cols) {
    const int32_t b = cols.begin(), e = cols.end();
    for (int32_t y = 2; y <= h; ++y) {
      const uint64_t* above = t + size_t(y - 1) * st;
      uint64_t* row = t + size_t(y) * st;
      for (int32_t x = b; x < e; ++x) row[x] += above[x];
    }
  });
  return s;
}

uint64_t Sat::cost(const Rect& r) const {
  const Rect i = intersect(r, packets_);
  if (i.empty()) return 0;
  return cost_inside(i);
}

void Sat::serialize_into(std::vector<uint8_t>& out) const {
  const int32_t w = packets_.width(), h = packets_.height();
  const uint64_t count = empty() ? 0 : uint64_t(w) * uint64_t(h);
  out.resize(kHeaderBytes + count * 8);
  uint8_t* p = out.data();
  std::memcpy(p, kMagic, 4);
  put_u16(p + 4, kVersion);
  put_u16(p + 6, uint16_t(kHeaderBytes));
  put_u32(p + 8, uint32_t(packets_.x0));
  put_u32(p + 12, uint32_t(packets_.y0));
  put_u32(p + 16, uint32_t(packets_.x1));
  put_u32(p + 20, uint32_t(packets_.y1));
  put_u64(p + 24, count);
  if (count == 0) return;
  uint8_t* d = p + kHeaderBytes;
  for (int32_t y = 1; y <= h; ++y) {
    const uint64_t* row = table_.get() + size_t(y) * stride_ + 1;
#if defined(__BYTE_ORDER__) && __BYTE_ORDER__ == __ORDER_LITTLE_ENDIAN__
    std::memcpy(d, row, size_t(w) * 8);
    d += size_t(w) * 8;
#else
    for (int32_t x = 0; x < w; ++x, d += 8) put_u64(d, row[x]);
#endif
  }
}

std::vector<uint8_t> Sat::serialize() const {
  std::vector<uint8_t> out;
  serialize_into(out);
  return out;
}

std::optional<Sat> Sat::try_deserialize(const uint8_t* data, size_t size, std::string* error) noexcept {
  try {
    return deserialize(data, size);
  } catch (const std::exception& e) {
    if (error) *error = e.what();
  }
  return std::nullopt;
}

Sat Sat::deserialize(const uint8_t* data, size_t size) {
  auto fail = [](const std::string& what) -> SatFormatError { return SatFormatError("SAT buffer: " + what); };
  if (data == nullptr && size != 0) throw fail("null data");
  if (size < kHeaderBytes)
    throw fail("truncated header (" + std::to_string(size) + " of " + std::to_string(kHeaderBytes) + " bytes)");
  if (std::memcmp(data, kMagic, 4) != 0) throw fail("bad magic (not a TSAT buffer)");
  if (get_u16(data + 4) != kVersion) throw fail("unsupported version " + std::to_string(get_u16(data + 4)));
  if (get_u16(data + 6) != kHeaderBytes) throw fail("bad header size " + std::to_string(get_u16(data + 6)));
  const Rect r{int32_t(get_u32(data + 8)), int32_t(get_u32(data + 12)), int32_t(get_u32(data + 16)),
               int32_t(get_u32(data + 20))};
  const uint64_t count = get_u64(data + 24);
  if (r.x0 < 0 || r.y0 < 0 || r.x1 < r.x0 || r.y1 < r.y0 || r.x1 > kMaxCoord || r.y1 > kMaxCoord) {
    std::ostringstream os;
    os << "impossible rectangle [" << r.x0 << "," << r.x1 << ")x[" << r.y0 << "," << r.y1 << ")";
    throw fail(os.str());
  }
  const uint64_t w = uint64_t(r.width()), h = uint64_t(r.height());
  const uint64_t expect = (w == 0 || h == 0) ? 0 : w * h;
  if (count != expect) {
    std::ostringstream os;
    os << "count " << count << " does not match the rectangle " << w << "x" << h;
    throw fail(os.str());
  }
  if (count > kMaxEntries) throw fail("SAT of " + std::to_string(count) + " entries is too large");
  if (size != kHeaderBytes + count * 8) {
    std::ostringstream os;
    os << (size < kHeaderBytes + count * 8 ? "truncated" : "trailing bytes") << ": " << size << " bytes, expected "
       << kHeaderBytes + count * 8;
    throw fail(os.str());
  }
  if (count == 0) return Sat(r.empty() ? Rect{} : r);
  Sat s(r);
  const uint8_t* d = data + kHeaderBytes;
  uint64_t* t = s.table_.get();
  const size_t st = s.stride_;
  // Copy and check that every implied packet cost lies in [0, 2^32): then the table is
  // exactly the SAT of a 32-bit cost map (all arithmetic is modulo 2^64).
  for (uint64_t y = 1; y <= h; ++y) {
    uint64_t* row = t + y * st;
    const uint64_t* above = row - st;
    for (uint64_t x = 1; x <= w; ++x, d += 8) {
      row[x] = get_u64(d);
      const uint64_t c = row[x] - above[x] - row[x - 1] + above[x - 1];
      if (c > 0xffffffffull) {
        std::ostringstream os;
        os << "corrupt entry at packet (" << r.x0 + int64_t(x) - 1 << "," << r.y0 + int64_t(y) - 1
           << "): implied packet cost is negative or exceeds 32 bits";
        throw fail(os.str());
      }
    }
  }
  return s;
}

// ---------------------------------------------------------------------------------------------

SatArray::SatArray(Rect packet_space) : space_(packet_space) {
  if (packet_space.x0 < 0 || packet_space.y0 < 0 || packet_space.x1 < packet_space.x0 ||
      packet_space.y1 < packet_space.y0)
    throw std::invalid_argument("SatArray: invalid packet space");
}

void SatArray::add(Sat sat, double single_core_perf) {
  if (!(std::isfinite(single_core_perf) && single_core_perf > 0)) {
    std::ostringstream os;
    os << "SatArray::add: single-core performance coefficient " << single_core_perf << " must be finite and > 0";
    throw std::invalid_argument(os.str());
  }
  if (sat.empty()) return;
  const Rect& r = sat.packets();
  if (!space_.contains(r)) {
    std::ostringstream os;
    os << "SatArray::add: SAT [" << r.x0 << "," << r.x1 << ")x[" << r.y0 << "," << r.y1
       << ") lies outside the packet space [" << space_.x0 << "," << space_.x1 << ")x[" << space_.y0 << ","
       << space_.y1 << ")";
    throw std::invalid_argument(os.str());
  }
  entries_.push_back(Entry{std::move(sat), single_core_perf});
  finalized_ = false;
}

void SatArray::finalize() {
  std::stable_sort(entries_.begin(), entries_.end(),
                   [](const Entry& a, const Entry& b) { return a.sat.packets().x0 < b.sat.packets().x0; });
  x0s_.resize(entries_.size());
  known_area_ = 0;
  known_cost_ = 0;
  for (size_t i = 0; i < entries_.size(); ++i) {
    const Rect& a = entries_[i].sat.packets();
    x0s_[i] = a.x0;
    // Overlap check: only SATs starting before a ends can overlap it.
    for (size_t j = i + 1; j < entries_.size() && entries_[j].sat.packets().x0 < a.x1; ++j) {
      if (!intersect(a, entries_[j].sat.packets()).empty()) {
        const Rect& b = entries_[j].sat.packets();
        std::ostringstream os;
        os << "SatArray: SATs [" << a.x0 << "," << a.x1 << ")x[" << a.y0 << "," << a.y1 << ") and [" << b.x0
           << "," << b.x1 << ")x[" << b.y0 << "," << b.y1 << ") overlap";
        throw std::invalid_argument(os.str());
      }
    }
    known_area_ += a.area();
    known_cost_ += double(entries_[i].sat.total()) * entries_[i].perf;
  }
  const int64_t missing = space_.area() - known_area_;
  missing_density_ = (known_area_ > 0 && known_cost_ > 0) ? known_cost_ / double(known_area_) : 1.0;
  total_ = known_cost_ + (missing > 0 ? missing_density_ * double(missing) : 0.0);
  finalized_ = true;
}

double SatArray::cost(const Rect& q) const {
  if (!finalized_) throw std::logic_error("SatArray::cost: finalize() was not called");
  const Rect r = intersect(q, space_);
  if (r.empty()) return 0;
  // SATs starting at or beyond r.x1 cannot contribute.
  const size_t end = size_t(std::lower_bound(x0s_.begin(), x0s_.end(), r.x1) - x0s_.begin());
  double sum = 0;
  int64_t covered = 0;
  for (size_t i = 0; i < end; ++i) {
    const Entry& e = entries_[i];
    const Rect& s = e.sat.packets();
    if (s.x1 <= r.x0 || s.y1 <= r.y0 || s.y0 >= r.y1) continue;
    const Rect c{std::max(r.x0, s.x0), std::max(r.y0, s.y0), std::min(r.x1, s.x1), std::min(r.y1, s.y1)};
    sum += double(e.sat.cost_inside(c)) * e.perf;
    covered += c.area();
  }
  if (covered < r.area()) sum += missing_density_ * double(r.area() - covered);
  return sum;
}

CostMap SatArray::cost_map() const {
  if (!finalized_) throw std::logic_error("SatArray::cost_map: finalize() was not called");
  const int32_t W = space_.width();
  const auto unit = [](double v) { return uint32_t(std::llround(std::min(std::max(v, 0.0), 4294967295.0))); };
  CostMap out{space_, std::vector<uint32_t>(size_t(space_.area()), unit(missing_density_))};
  for (const Entry& e : entries_) {
    const Rect& r = e.sat.packets();
    const uint64_t* t = e.sat.table();
    const size_t s = e.sat.stride();
    for (int32_t j = 0; j < r.height(); ++j)
      for (int32_t i = 0; i < r.width(); ++i) {
        const uint64_t c = t[size_t(j + 1) * s + size_t(i + 1)] - t[size_t(j) * s + size_t(i + 1)] -
                           t[size_t(j + 1) * s + size_t(i)] + t[size_t(j) * s + size_t(i)];
        out.cost[size_t(r.y0 + j - space_.y0) * size_t(W) + size_t(r.x0 + i - space_.x0)] = unit(double(c) * e.perf);
      }
  }
  return out;
}

}  // namespace tessera
