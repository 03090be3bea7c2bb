// SharedBytes (core/shared_bytes.h): a texture's bytes, shared by its copies until one writes.
#include <catch2/catch.hpp>

#include "core/scene.h"
#include "core/shared_bytes.h"

using namespace tessera;

TEST_CASE("Copies of SharedBytes share the bytes until one of them writes; the others keep theirs", "[unit]") {
  SharedBytes a(std::vector<uint8_t>{1, 2, 3, 4});
  const uint8_t* before = a.data();
  SharedBytes b = a;
  CHECK(b.same(a));
  CHECK(b.data() == before);  // no copy
  const SharedBytes& cb = b;
  CHECK(int(cb[2]) == 3);  // a read through a const view copies nothing
  CHECK(b.same(a));
  b[0] = 9;  // a write: b takes its own copy first
  CHECK_FALSE(b.same(a));
  CHECK(a.data() == before);
  CHECK(int(a[0]) == 1);
  CHECK(int(b[0]) == 9);
  CHECK(b == std::vector<uint8_t>{9, 2, 3, 4});
  // Alone again, a writes in place.
  b = SharedBytes();
  a[1] = 7;
  CHECK(a.data() == before);
  CHECK(a == SharedBytes{1, 7, 3, 4});
  CHECK(a != SharedBytes{1, 2, 3, 4});
}

TEST_CASE("SharedBytes never writes into bytes it shares from elsewhere, and a moved-from one is empty and usable",
          "[unit]") {
  auto cached = std::make_shared<const std::vector<uint8_t>>(std::vector<uint8_t>{5, 6, 7});
  SharedBytes t(cached);
  CHECK(t.data() == cached->data());
  t.push_back(8);  // the cache's bytes stay as they were
  CHECK(*cached == std::vector<uint8_t>{5, 6, 7});
  CHECK(t == std::vector<uint8_t>{5, 6, 7, 8});
  cached.reset();
  // Even as the last holder of shared bytes, the first write copies (they may be const).
  SharedBytes u(std::make_shared<const std::vector<uint8_t>>(std::vector<uint8_t>{1}));
  const uint8_t* shared = u.data();
  u[0] = 2;
  CHECK(u.data() != shared);
  CHECK(int(u[0]) == 2);

  SharedBytes m = std::move(t);
  CHECK(m.size() == 4);
  CHECK(t.empty());  // NOLINT(bugprone-use-after-move): a moved-from value is empty, as documented
  t.push_back(1);
  CHECK(t.size() == 1);
  CHECK(m.size() == 4);
  SharedBytes e;
  CHECK(e.empty());
  CHECK(e.data() == nullptr);
  CHECK(e.begin() == e.end());
  e.assign(3, 4);
  CHECK(e == std::vector<uint8_t>{4, 4, 4});
  e.insert(e.end(), {1, 2});
  CHECK(e == std::vector<uint8_t>{4, 4, 4, 1, 2});
  e.clear();
  CHECK(e.empty());
}

TEST_CASE("A copied texture shares its texels with the original", "[unit]") {
  Texture t;
  t.width = 2, t.height = 1;
  t.rgba = {1, 2, 3, 4, 5, 6, 7, 8};
  Texture c = t;
  CHECK(c.rgba.same(t.rgba));
  c.rgba[0] = 0;
  CHECK(int(t.rgba[0]) == 1);
}
