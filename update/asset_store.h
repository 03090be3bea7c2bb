#pragma once
// References (docs/protocol.md, "References"): buffers and textures a node loads itself from a
// URL instead of a client uploading them, and the node-wide cache of what it decoded.
//
// What a node loads: a URL on the node's own origin (the origin the client reached it at) whose
// path is under /scenes/ is read from the scenes folder the node serves there; a URL of an
// origin the operator listed (tessera.asset-origins) is fetched over HTTP(S). Nothing else:
// arbitrary URLs would let any page make the node request what it can reach (server-side
// request forgery). Redirects are not followed.
//
// The cache holds decoded textures keyed by the SHA-256 of the file's bytes (never by URL), so
// a changed file is decoded again and never served stale, and equal files share one entry.
// It is bounded (least recently used first out). Files are read, or fetched, each time: the
// content hash is what tells whether they changed.
#include <cstdint>
#include <functional>
#include <list>
#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include "core/image.h"
#include "protocol/protocol.h"

namespace tessera {

struct AssetOptions {
  std::string scenes_root;             // served at /scenes/ ("": no file references)
  std::vector<std::string> origins;    // further origins ("https://cdn.example") fetched over HTTP(S)
  uint64_t cache_bytes = 512ull << 20;  // decoded textures kept for later sessions
  uint64_t max_file_bytes = 1ull << 30; // a referenced file larger than this is refused
};

// GET `url` (an allowed origin's); the body, at most max_bytes, or false and why.
using AssetFetch = std::function<bool(const std::string& url, uint64_t max_bytes, std::vector<uint8_t>& body,
                                      std::string& error)>;

// One file as a reference found it: its bytes and their SHA-256 (hex).
struct AssetFile {
  std::shared_ptr<const std::vector<uint8_t>> bytes;
  std::string hash;
};

struct AssetStats {
  uint64_t hits = 0, misses = 0, evictions = 0;  // texture lookups in the cache
  uint64_t bytes = 0, entries = 0;               // held now
};

class AssetStore {
 public:
  explicit AssetStore(AssetOptions options, AssetFetch fetch = {});

  // The message's references resolved into buffer and texture records, in place: each
  // SetBufferRef or SetTextureRef in `records` becomes a SetBuffer or SetTexture, or stays
  // as it was when refused; `answers` gets one Reference per reference, in order (bytes: the
  // content's size; message: why it was refused). Files named more than once are read once.
  // Textures that miss the cache are decoded in parallel. `node_origin`: "http://host:port"
  // as the client reached this node ("": none of its own files). Thread-safe.
  void resolve(std::vector<protocol::ClientRecord>& records, const std::string& node_origin,
               const protocol::Limits& limits, std::vector<protocol::Reference>& answers);

  AssetStats stats() const;
  const AssetOptions& options() const { return options_; }

  // Pieces of resolve(), public for the tests.
  // Where `url` is loaded from: the file under scenes_root, or the URL itself for an allowed
  // origin; false and why not.
  enum class Where { file, http };
  bool locate(const std::string& url, const std::string& node_origin, Where& where, std::string& target,
              std::string& error) const;
  // The file's bytes and hash, read or fetched; false and why not.
  bool load(const std::string& url, const std::string& node_origin, AssetFile& out, std::string& error) const;
  // The decoded texture of this file, from the cache or decoded (and cached); null and why not.
  std::shared_ptr<const Image> texture(const AssetFile& file, int32_t max_size, std::string& error);

 private:
  void insert(const std::string& hash, std::shared_ptr<const Image> img);

  AssetOptions options_;
  AssetFetch fetch_;
  mutable std::mutex mu_;
  std::list<std::string> lru_;  // hashes, most recently used first
  struct Entry {
    std::shared_ptr<const Image> image;
    std::list<std::string>::iterator at;
  };
  std::map<std::string, Entry> cache_;
  AssetStats stats_;
};

// SHA-256 of the bytes, as 64 lower-case hex digits.
std::string sha256_hex(const uint8_t* data, size_t size);

}  // namespace tessera
