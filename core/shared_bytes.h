#pragma once
// Bytes that copies share until one of them is written: a texture's RGBA8 texels (core/scene.h).
//
// A decoded image is hundreds of megabytes in a big scene (a San Miguel-sized one: 0.9 GB).
// The node's texture cache, every session's scene model that uses the image and every
// renderer that shows it hold the same bytes instead of a copy each (docs/results/load.md).
// Reading never copies; a write through a non-const accessor (operator[], begin, assign,
// resize, ...) first takes a private copy when anyone else holds the bytes, so a holder keeps
// what it had: a renderer keeps showing a texture until its next sync, whatever the session
// does to its scene meanwhile.
//
// Thread safety: as std::shared_ptr. Holders on different threads each own their SharedBytes;
// one object is not written from two threads at once.
#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <initializer_list>
#include <memory>
#include <utility>
#include <vector>

namespace tessera {

class SharedBytes {
 public:
  using Vec = std::vector<uint8_t>;
  using const_iterator = Vec::const_iterator;
  using iterator = Vec::iterator;

  SharedBytes() = default;
  SharedBytes(Vec v) {  // NOLINT: implicit, as the vector it replaces
    if (!v.empty()) own(std::make_shared<Vec>(std::move(v)));
  }
  SharedBytes(std::initializer_list<uint8_t> l) : SharedBytes(Vec(l)) {}
  // Shares bytes held elsewhere (for instance an image in a cache, through shared_ptr's
  // aliasing constructor); they are never written through this object.
  explicit SharedBytes(std::shared_ptr<const Vec> p) : p_(std::move(p)) {}
  SharedBytes(const SharedBytes&) = default;
  SharedBytes& operator=(const SharedBytes&) = default;
  SharedBytes(SharedBytes&& o) noexcept : p_(std::move(o.p_)), mine_(std::exchange(o.mine_, nullptr)) {}
  SharedBytes& operator=(SharedBytes&& o) noexcept {
    p_ = std::move(o.p_);
    mine_ = std::exchange(o.mine_, nullptr);
    return *this;
  }

  const uint8_t* data() const { return p_ ? p_->data() : nullptr; }
  size_t size() const { return p_ ? p_->size() : 0; }
  bool empty() const { return size() == 0; }
  const uint8_t& operator[](size_t i) const { return (*p_)[i]; }
  const_iterator begin() const { return p_ ? p_->begin() : empty_().begin(); }
  const_iterator end() const { return p_ ? p_->end() : empty_().end(); }
  // Whether both hold the very same bytes (not merely equal ones).
  bool same(const SharedBytes& o) const { return p_ == o.p_; }

  // Writers: the bytes become this object's own first (mut()).
  uint8_t& operator[](size_t i) { return mut()[i]; }
  iterator begin() { return mut().begin(); }
  iterator end() { return mut().end(); }
  void clear() { *this = SharedBytes(); }
  void resize(size_t n) { mut().resize(n); }
  void push_back(uint8_t v) { mut().push_back(v); }
  void assign(size_t n, uint8_t v) {
    if (mine_ && p_.use_count() == 1) mine_->assign(n, v);
    else own(std::make_shared<Vec>(n, v));
  }
  template <class It>
  void assign(It first, It last) {
    if (mine_ && p_.use_count() == 1) mine_->assign(first, last);
    else own(std::make_shared<Vec>(first, last));
  }
  template <class It>
  iterator insert(It pos, std::initializer_list<uint8_t> l) {
    const auto at = pos - It(begin());
    Vec& v = mut();
    return v.insert(v.begin() + at, l);
  }

  friend bool operator==(const SharedBytes& a, const SharedBytes& b) {
    return a.p_ == b.p_ || std::equal(a.begin(), a.end(), b.begin(), b.end());
  }
  friend bool operator!=(const SharedBytes& a, const SharedBytes& b) { return !(a == b); }
  friend bool operator==(const SharedBytes& a, const Vec& b) { return std::equal(a.begin(), a.end(), b.begin(), b.end()); }
  friend bool operator==(const Vec& a, const SharedBytes& b) { return b == a; }

 private:
  Vec& mut() {
    if (!mine_ || p_.use_count() > 1) own(p_ ? std::make_shared<Vec>(*p_) : std::make_shared<Vec>());
    return *mine_;
  }
  static const Vec& empty_() {
    static const Vec e;
    return e;
  }
  void own(std::shared_ptr<Vec> v) {
    mine_ = v.get();
    p_ = std::move(v);
  }
  std::shared_ptr<const Vec> p_;
  Vec* mine_ = nullptr;  // p_'s bytes when this object (or a copy of it) made them, else null
};

}  // namespace tessera
