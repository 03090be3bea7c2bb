// References (update/asset_store.h): what a node loads itself, and its cache of decoded textures.
#include <catch2/catch.hpp>

#include <cstring>
#include <filesystem>
#include <fstream>
#include <utility>

#include "core/image.h"
#include "tests/unit/temp_files.h"
#include "update/asset_store.h"

using namespace tessera;
using namespace tessera::protocol;
using tessera::test::TempDir;

namespace {

const std::string kNode = "http://127.0.0.1:8080";

Image solid(int w, int h, uint8_t r, uint8_t g, uint8_t b) {
  Image img(w, h);
  for (size_t i = 0; i < img.rgba.size(); i += 4) img.rgba[i] = r, img.rgba[i + 1] = g, img.rgba[i + 2] = b, img.rgba[i + 3] = 255;
  return img;
}

SetTextureRef tex_ref(Id id, const std::string& url) {
  SetTextureRef t;
  t.id = id;
  t.url = url;
  return t;
}

// Resolves one record; returns its answer (the record is changed in place).
Reference one(AssetStore& store, ClientRecord& rec, const Limits& lim = {}) {
  std::vector<ClientRecord> recs{rec};
  std::vector<Reference> answers;
  store.resolve(recs, kNode, lim, answers);
  REQUIRE(answers.size() == 1);
  rec = recs[0];
  return answers[0];
}

}  // namespace

TEST_CASE("A reference is loaded only from the node's own /scenes/ or a listed origin", "[assets]") {
  TempDir dir("assets");
  std::filesystem::create_directories(dir.path + "/scenes/a");
  dir.write("scenes/a/x.bin", "0123");
  dir.write("secret.txt", "no");
  AssetOptions o;
  o.scenes_root = dir.path + "/scenes";
  o.origins = {"https://CDN.example:443", "http://assets.example:8081"};
  AssetStore store(o, [](const std::string&, uint64_t, std::vector<uint8_t>&, std::string&) { return false; });
  AssetStore::Where where;
  std::string target, error;

  CHECK(store.locate("http://127.0.0.1:8080/scenes/a/x.bin", kNode, where, target, error));
  CHECK(where == AssetStore::Where::file);
  CHECK(target == std::filesystem::weakly_canonical(dir.path + "/scenes/a/x.bin").string());
  // The same origin written otherwise (case, the default port) and a query and fragment.
  CHECK(store.locate("HTTP://127.0.0.1:8080/scenes/a/x.bin?v=1#f", kNode, where, target, error));
  CHECK(store.locate("http://localhost/scenes/a/x.bin", "http://LOCALHOST:80", where, target, error));
  CHECK(where == AssetStore::Where::file);

  // Listed origins are fetched (normalised: lower case, no default port).
  CHECK(store.locate("https://cdn.example/t/a.png", kNode, where, target, error));
  CHECK(where == AssetStore::Where::http);
  CHECK(target == "https://cdn.example/t/a.png");
  CHECK(store.locate("http://assets.example:8081/b.bin?x=2#y", kNode, where, target, error));
  CHECK(target == "http://assets.example:8081/b.bin?x=2");

  // Refused, each with a reason that names what to change.
  auto refused = [&](const std::string& url, const std::string& why, const std::string& node = kNode) {
    error.clear();
    INFO(url);
    CHECK_FALSE(store.locate(url, node, where, target, error));
    CHECK(error.find(why) != std::string::npos);
  };
  refused("http://evil.example/scenes/a/x.bin", "nor in its tessera.asset-origins");
  refused("http://127.0.0.1:8081/scenes/a/x.bin", "nor in its tessera.asset-origins");  // another port
  refused("https://127.0.0.1:8080/scenes/a/x.bin", "nor in its tessera.asset-origins");  // another scheme
  refused("http://assets.example/b.bin", "nor in its tessera.asset-origins");            // the listed one has :8081
  refused("http://127.0.0.1:8080/secret.txt", "only files under /scenes/");
  refused("http://127.0.0.1:8080/scenes/../secret.txt", "no file of this node's /scenes/");
  refused("http://127.0.0.1:8080/scenes/a/%2e%2e/%2e%2e/secret.txt", "no file of this node's /scenes/");
  refused("http://127.0.0.1:8080/scenes/a/missing.bin", "no file of this node's /scenes/");
  refused("http://127.0.0.1:8080/scenes/a/", "no file of this node's /scenes/");
  refused("file:///etc/passwd", "not an absolute http(s) URL");
  refused("http://user@127.0.0.1:8080/scenes/a/x.bin", "not an absolute http(s) URL");
  refused("http://127.0.0.1:99999/scenes/a/x.bin", "not an absolute http(s) URL");
  refused("/scenes/a/x.bin", "not an absolute http(s) URL");
  // A client that reached the node by no known origin names none of its files.
  refused("http://127.0.0.1:8080/scenes/a/x.bin", "nor in its tessera.asset-origins", "");

  // A store without a fetch function fetches nothing, listed or not.
  AssetStore files_only(o);
  error.clear();
  CHECK_FALSE(files_only.locate("https://cdn.example/t/a.png", kNode, where, target, error));
  CHECK(error == "this node fetches no URLs");
  // A listed entry that is not an origin is a configuration error.
  AssetOptions bad = o;
  bad.origins = {"https://cdn.example/path"};
  CHECK_THROWS_WITH(AssetStore(bad), Catch::Contains("is not an origin"));
}

TEST_CASE("Buffer references slice, de-interleave and widen the file's values", "[assets]") {
  TempDir dir("assets");
  std::filesystem::create_directories(dir.path + "/s");
  // 8 bytes of header, then 3 interleaved vertices (position float3 + uv float2: stride 20),
  // then 3 uint16 indices and 3 uint8 indices.
  std::string bin(8, 'h');
  const float v[3][5] = {{1, 2, 3, 0.1f, 0.2f}, {4, 5, 6, 0.3f, 0.4f}, {7, 8, 9, 0.5f, 0.6f}};
  bin.append(reinterpret_cast<const char*>(v), sizeof v);
  const uint16_t i16[3] = {2, 65535, 0};
  bin.append(reinterpret_cast<const char*>(i16), sizeof i16);
  bin += std::string("\x07\xff\x00", 3);
  dir.write("s/m.bin", bin);
  AssetOptions o;
  o.scenes_root = dir.path + "/s";
  AssetStore store(o);
  const std::string url = kNode + "/scenes/m.bin";

  SetBufferRef pos;
  pos.id = 1, pos.type = Buffer::Type::f32, pos.components = 3, pos.source = SourceType::f32;
  pos.value_count = 9, pos.byte_stride = 20, pos.byte_offset = 8, pos.url = url;
  SetBufferRef uv = pos;
  uv.id = 2, uv.components = 2, uv.value_count = 6, uv.byte_offset = 8 + 12;
  SetBufferRef packed = pos;
  packed.id = 3, packed.components = 1, packed.value_count = 5, packed.byte_stride = 0;  // the first 5 floats
  SetBufferRef idx16;
  idx16.id = 4, idx16.type = Buffer::Type::u32, idx16.components = 1, idx16.source = SourceType::u16;
  idx16.value_count = 3, idx16.byte_offset = 8 + 60, idx16.url = url;
  SetBufferRef idx8 = idx16;
  idx8.id = 5, idx8.source = SourceType::u8, idx8.byte_offset = 8 + 66;
  std::vector<ClientRecord> recs{pos, uv, packed, idx16, idx8, RenderRequest{1}};
  std::vector<Reference> answers;
  store.resolve(recs, kNode, Limits{}, answers);
  REQUIRE(answers.size() == 5);
  for (const Reference& a : answers) {
    INFO(a.message);
    CHECK(a.ok);
    CHECK(a.what == RefKind::buffer);
  }
  CHECK(answers[0].id == 1);
  CHECK(answers[0].bytes == 36);
  CHECK(std::get<SetBuffer>(recs[0]).buffer.f == std::vector<float>{1, 2, 3, 4, 5, 6, 7, 8, 9});
  CHECK(std::get<SetBuffer>(recs[1]).buffer.f == std::vector<float>{0.1f, 0.2f, 0.3f, 0.4f, 0.5f, 0.6f});
  CHECK(std::get<SetBuffer>(recs[1]).buffer.components == 2);
  CHECK(std::get<SetBuffer>(recs[2]).buffer.f == std::vector<float>{1, 2, 3, 0.1f, 0.2f});
  CHECK(std::get<SetBuffer>(recs[3]).buffer.u == std::vector<uint32_t>{2, 65535, 0});
  CHECK(std::get<SetBuffer>(recs[4]).buffer.u == std::vector<uint32_t>{7, 255, 0});
  CHECK(std::get<SetBuffer>(recs[4]).id == 5);
  CHECK(std::holds_alternative<RenderRequest>(recs[5]));  // the other records are left alone

  // Beyond the file's end (by one byte, and from an offset past it): refused, and left as it was.
  SetBufferRef over = idx8;
  over.value_count = 4;
  ClientRecord r = over;
  Reference a = one(store, r);
  CHECK_FALSE(a.ok);
  CHECK(a.message.find("buffer 5 (" + url + "): the file holds 77 bytes; the buffer reads up to byte 78") == 0);
  CHECK(std::holds_alternative<SetBufferRef>(r));
  over.byte_offset = ~0ull - 2;
  r = over;
  CHECK_FALSE(one(store, r).ok);
  // Beyond the message's payload limit.
  Limits small;
  small.max_message_payload_bytes = 35;
  r = pos;
  a = one(store, r, small);
  CHECK_FALSE(a.ok);
  CHECK(a.message.find("exceed the limit of 35 bytes") != std::string::npos);
}

TEST_CASE("Texture references decode once per content: the cache is keyed by hash, bounded, never stale", "[assets]") {
  TempDir dir("assets");
  std::filesystem::create_directories(dir.path + "/s");
  const std::string a_png = dir.path + "/s/a.png", b_png = dir.path + "/s/b.png";
  write_png(a_png, solid(16, 8, 200, 10, 10));
  write_png(b_png, solid(16, 8, 10, 200, 10));
  AssetOptions o;
  o.scenes_root = dir.path + "/s";
  o.cache_bytes = 16 * 8 * 4;  // room for one of them
  AssetStore store(o);

  ClientRecord r = tex_ref(7, kNode + "/scenes/a.png");
  Reference ans = one(store, r);
  REQUIRE(ans.ok);
  CHECK(ans.what == RefKind::texture);
  CHECK(ans.bytes == 16 * 8 * 4);
  const SetTexture& t = std::get<SetTexture>(r);
  CHECK(t.id == 7);
  CHECK(t.texture.width == 16);
  CHECK(t.texture.height == 8);
  CHECK(int(t.texture.rgba[0]) == 200);
  CHECK(store.stats().misses == 1);
  CHECK(store.stats().entries == 1);
  const SharedBytes first = t.texture.rgba;

  // A second session's reference to the same file: from the cache, the very same bytes (the
  // sessions share them with the cache instead of holding a copy each).
  r = tex_ref(8, kNode + "/scenes/a.png");
  REQUIRE(one(store, r).ok);
  CHECK(store.stats().hits == 1);
  CHECK(std::get<SetTexture>(std::as_const(r)).texture.rgba.same(first));
  CHECK(int(std::get<SetTexture>(r).texture.rgba[0]) == 200);

  // The file changes under the same URL: its new content, decoded again (the key is the hash).
  write_png(a_png, solid(16, 8, 1, 2, 250));
  r = tex_ref(7, kNode + "/scenes/a.png");
  REQUIRE(one(store, r).ok);
  CHECK(int(std::get<SetTexture>(r).texture.rgba[2]) == 250);
  CHECK(store.stats().misses == 2);
  // Only one fits: the old content was evicted.
  CHECK(store.stats().entries == 1);
  CHECK(store.stats().evictions == 1);
  CHECK(store.stats().bytes <= o.cache_bytes);

  // Another file of the same content as one cached: a hit (equal files share an entry).
  write_png(b_png, solid(16, 8, 1, 2, 250));
  r = tex_ref(9, kNode + "/scenes/b.png");
  REQUIRE(one(store, r).ok);
  CHECK(store.stats().hits == 2);

  // Not an image, too large for the limit, missing: refused with the reason.
  dir.write("s/c.png", "not an image");
  r = tex_ref(10, kNode + "/scenes/c.png");
  ans = one(store, r);
  CHECK_FALSE(ans.ok);
  CHECK(ans.message == "texture 10 (" + kNode + "/scenes/c.png): not a PNG or JPEG file");
  Limits small;
  small.max_texture_size = 8;
  r = tex_ref(11, kNode + "/scenes/b.png");
  ans = one(store, r, small);
  CHECK_FALSE(ans.ok);
  CHECK(ans.message.find("16x8, beyond the limit 8") != std::string::npos);
  write_png(dir.path + "/s/d.png", solid(16, 9, 0, 0, 0));  // not cached: the header check
  r = tex_ref(12, kNode + "/scenes/d.png");
  CHECK_FALSE(one(store, r, small).ok);
}

TEST_CASE("A listed origin's files come through the fetch function, each URL once per message", "[assets]") {
  std::vector<std::string> asked;
  std::string bin(12, '\0');
  const float f[3] = {1.5f, -2, 4};
  std::memcpy(bin.data(), f, 12);
  AssetOptions o;
  o.origins = {"https://cdn.example"};
  AssetStore store(o, [&](const std::string& url, uint64_t max_bytes, std::vector<uint8_t>& body, std::string& error) {
    asked.push_back(url);
    CHECK(max_bytes == o.max_file_bytes);
    if (url.find("missing") != std::string::npos) {
      error = url + ": HTTP 404";
      return false;
    }
    body.assign(bin.begin(), bin.end());
    return true;
  });
  SetBufferRef a;
  a.id = 1, a.components = 1, a.value_count = 3, a.url = "https://cdn.example/m.bin";
  SetBufferRef b = a;
  b.id = 2, b.value_count = 1, b.byte_offset = 8;
  SetBufferRef c = a;
  c.id = 3, c.url = "https://cdn.example/missing.bin";
  std::vector<ClientRecord> recs{a, b, c};
  std::vector<Reference> answers;
  store.resolve(recs, kNode, Limits{}, answers);
  CHECK(asked == std::vector<std::string>{"https://cdn.example/m.bin", "https://cdn.example/missing.bin"});
  REQUIRE(answers.size() == 3);
  CHECK(answers[0].ok);
  CHECK(answers[1].ok);
  CHECK(std::get<SetBuffer>(recs[1]).buffer.f == std::vector<float>{4});
  CHECK_FALSE(answers[2].ok);
  CHECK(answers[2].message == "buffer 3 (https://cdn.example/missing.bin): https://cdn.example/missing.bin: HTTP 404");
}

TEST_CASE("sha256_hex matches the standard's test vectors", "[assets]") {
  CHECK(sha256_hex(reinterpret_cast<const uint8_t*>("abc"), 3) ==
        "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad");
  CHECK(sha256_hex(nullptr, 0) == "e3b0c44298fc1c149afbf4c8996fb92427ae41e4649b934ca495991b7852b855");
}
