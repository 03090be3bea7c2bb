#include "update/asset_store.h"

#include <openssl/evp.h>
#include <sys/stat.h>

#include <algorithm>
#include <cctype>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <unordered_map>

#include <tbb/parallel_for.h>

#include "codecs/jpeg.h"
#include "core/static_path.h"

namespace tessera {

using namespace protocol;

std::string sha256_hex(const uint8_t* data, size_t size) {
  unsigned char md[EVP_MAX_MD_SIZE];
  unsigned int n = 0;
  EVP_Digest(data, size, md, &n, EVP_sha256(), nullptr);
  static const char* digits = "0123456789abcdef";
  std::string out;
  out.reserve(size_t(n) * 2);
  for (unsigned i = 0; i < n; ++i) out += digits[md[i] >> 4], out += digits[md[i] & 15];
  return out;
}

namespace {

std::string lower(std::string s) {
  for (auto& c : s) c = char(std::tolower(static_cast<unsigned char>(c)));
  return s;
}

// An absolute http(s) URL split as far as the store needs: its origin (scheme://host[:port],
// lower case, the scheme's default port left out) and the path with its query (the fragment
// dropped). False: not one (another scheme, user info, no host, a bad port).
bool split_url(const std::string& url, std::string& origin, std::string& target) {
  const size_t colon = url.find("://");
  if (colon == std::string::npos) return false;
  const std::string scheme = lower(url.substr(0, colon));
  if (scheme != "http" && scheme != "https") return false;
  const size_t start = colon + 3, end = url.find_first_of("/?#", start);
  std::string authority = lower(url.substr(start, end == std::string::npos ? std::string::npos : end - start));
  if (authority.empty() || authority.find('@') != std::string::npos) return false;
  // host[:port], host possibly [v6]: the port is what follows the last ':' after any ']'.
  const size_t bracket = authority.rfind(']'), last = authority.rfind(':');
  if (last != std::string::npos && (bracket == std::string::npos || last > bracket)) {
    const std::string port = authority.substr(last + 1);
    if (port.empty() || port.size() > 5 || !std::all_of(port.begin(), port.end(), ::isdigit) || std::stoi(port) > 65535)
      return false;
    if ((scheme == "http" && std::stoi(port) == 80) || (scheme == "https" && std::stoi(port) == 443))
      authority.resize(last);
    else
      authority = authority.substr(0, last) + ":" + std::to_string(std::stoi(port));  // no leading zeros
  }
  if (authority.empty() || authority[0] == ':') return false;
  origin = scheme + "://" + authority;
  target = end == std::string::npos ? "/" : url.substr(end);
  if (target[0] != '/') target = "/" + target;  // "http://h?x"
  target = target.substr(0, target.find('#'));
  return true;
}

// The origin a configured entry names, normalised as split_url does ("" when it is not one).
std::string normal_origin(const std::string& text) {
  std::string origin, target;
  if (!split_url(text, origin, target) || (target != "/" && !target.empty())) return "";
  return origin;
}

bool read_file(const std::string& path, uint64_t max_bytes, std::vector<uint8_t>& out, std::string& error) {
  std::ifstream f(path, std::ios::binary | std::ios::ate);
  if (!f) {
    error = "cannot read " + path;
    return false;
  }
  const std::streamoff size = f.tellg();
  if (size < 0 || uint64_t(size) > max_bytes) {
    error = path + " holds " + std::to_string(size) + " bytes, more than the " + std::to_string(max_bytes) +
            " a referenced file may (tessera.asset-max-file-mb)";
    return false;
  }
  out.resize(size_t(size));
  f.seekg(0);
  if (size && !f.read(reinterpret_cast<char*>(out.data()), size)) {
    error = "cannot read " + path;
    return false;
  }
  return true;
}

const char* kind_name(RefKind k) { return k == RefKind::buffer ? "buffer" : "texture"; }

}  // namespace

AssetStore::AssetStore(AssetOptions options, AssetFetch fetch) : options_(std::move(options)), fetch_(std::move(fetch)) {
  for (auto& o : options_.origins) {
    const std::string n = normal_origin(o);
    if (n.empty()) throw std::runtime_error("tessera.asset-origins: '" + o + "' is not an origin (http(s)://host[:port])");
    o = n;
  }
}

bool AssetStore::locate(const std::string& url, const std::string& node_origin, Where& where, std::string& target,
                        std::string& error) const {
  std::string origin, path;
  if (!split_url(url, origin, path)) {
    error = "not an absolute http(s) URL without user info";
    return false;
  }
  const std::string own = normal_origin(node_origin);
  if (!own.empty() && origin == own) {
    static const std::string kScenes = "/scenes/";
    if (options_.scenes_root.empty() || path.compare(0, kScenes.size(), kScenes) != 0) {
      error = "on this node's origin only files under /scenes/ are loaded" +
              std::string(options_.scenes_root.empty() ? " (and this node serves none)" : "");
      return false;
    }
    auto file = resolve_static(options_.scenes_root, path.substr(kScenes.size() - 1));
    if (!file) {
      error = "no file of this node's /scenes/ at " + target_path(path);
      return false;
    }
    where = Where::file;
    target = *file;
    return true;
  }
  if (std::find(options_.origins.begin(), options_.origins.end(), origin) == options_.origins.end()) {
    error = origin + " is neither this node's origin" + (own.empty() ? std::string() : " (" + own + ")") +
            " nor in its tessera.asset-origins";
    return false;
  }
  if (!fetch_) {
    error = "this node fetches no URLs";
    return false;
  }
  where = Where::http;
  target = origin + path;
  return true;
}

bool AssetStore::load(const std::string& url, const std::string& node_origin, AssetFile& out, std::string& error) const {
  Where where;
  std::string target;
  if (!locate(url, node_origin, where, target, error)) return false;
  auto bytes = std::make_shared<std::vector<uint8_t>>();
  if (where == Where::file ? !read_file(target, options_.max_file_bytes, *bytes, error)
                           : !fetch_(target, options_.max_file_bytes, *bytes, error))
    return false;
  out.hash = sha256_hex(bytes->data(), bytes->size());
  out.bytes = std::move(bytes);
  return true;
}

void AssetStore::insert(const std::string& hash, std::shared_ptr<const Image> img) {
  const uint64_t size = img->rgba.size();
  if (size > options_.cache_bytes) return;
  if (cache_.count(hash)) return;
  while (stats_.bytes + size > options_.cache_bytes && !lru_.empty()) {
    auto it = cache_.find(lru_.back());
    stats_.bytes -= it->second.image->rgba.size();
    cache_.erase(it);
    lru_.pop_back();
    stats_.evictions++;
  }
  lru_.push_front(hash);
  cache_[hash] = Entry{std::move(img), lru_.begin()};
  stats_.bytes += size;
  stats_.entries = cache_.size();
}

std::shared_ptr<const Image> AssetStore::texture(const AssetFile& file, int32_t max_size, std::string& error) {
  {
    std::lock_guard<std::mutex> lock(mu_);
    auto it = cache_.find(file.hash);
    if (it != cache_.end()) {
      lru_.splice(lru_.begin(), lru_, it->second.at);
      stats_.hits++;
      const Image& img = *it->second.image;
      if (img.width > max_size || img.height > max_size) {
        error = "the image is " + std::to_string(img.width) + "x" + std::to_string(img.height) +
                ", beyond the limit " + std::to_string(max_size);
        return nullptr;
      }
      return it->second.image;
    }
    stats_.misses++;
  }
  const std::vector<uint8_t>& b = *file.bytes;
  uint32_t w = 0, h = 0;
  int jw = 0, jh = 0;
  std::string jerr;
  if (png_dimensions(b.data(), b.size(), w, h)) {
  } else if (jpeg_dimensions(b.data(), b.size(), jw, jh, jerr)) {
    w = uint32_t(jw), h = uint32_t(jh);
  } else {
    error = "not a PNG or JPEG file";
    return nullptr;
  }
  if (w == 0 || h == 0 || w > uint32_t(max_size) || h > uint32_t(max_size)) {
    error = "the image is " + std::to_string(w) + "x" + std::to_string(h) + ", beyond the limit " +
            std::to_string(max_size);
    return nullptr;
  }
  auto img = std::make_shared<Image>();
  const bool jpeg = jw > 0;  // libjpeg-turbo for JPEG files, stb for PNG
  if (!(jpeg ? jpeg_decode(b.data(), b.size(), *img, error) : decode_image(b.data(), b.size(), *img, error))) {
    if (error.empty()) error = "the image does not decode";
    return nullptr;
  }
  if (img->width != int32_t(w) || img->height != int32_t(h)) {
    error = "the image decodes to another size than its header's";
    return nullptr;
  }
  std::lock_guard<std::mutex> lock(mu_);
  insert(file.hash, img);
  return img;
}

AssetStats AssetStore::stats() const {
  std::lock_guard<std::mutex> lock(mu_);
  return stats_;
}

void AssetStore::resolve(std::vector<ClientRecord>& records, const std::string& node_origin, const Limits& limits,
                         std::vector<Reference>& answers) {
  // The files first, each URL once (the records of one glTF share its .bin).
  struct Loaded {
    AssetFile file;
    std::string error;
  };
  std::unordered_map<std::string, Loaded> files;
  auto file_of = [&](const std::string& url) -> Loaded& {
    auto it = files.find(url);
    if (it != files.end()) return it->second;
    Loaded& l = files[url];
    if (!load(url, node_origin, l.file, l.error)) l.file.bytes.reset();
    return l;
  };
  struct Job {
    size_t record;
    std::string url;
    Reference answer;
    std::shared_ptr<const Image> image;  // textures
  };
  std::vector<Job> jobs;
  for (size_t i = 0; i < records.size(); ++i) {
    if (auto* b = std::get_if<SetBufferRef>(&records[i]))
      jobs.push_back({i, b->url, Reference{RefKind::buffer, false, b->id, 0, {}}, nullptr});
    else if (auto* t = std::get_if<SetTextureRef>(&records[i]))
      jobs.push_back({i, t->url, Reference{RefKind::texture, false, t->id, 0, {}}, nullptr});
    else
      continue;
    Loaded& l = file_of(jobs.back().url);
    if (!l.file.bytes) jobs.back().answer.message = l.error;
  }
  // Textures decode in parallel (those in the cache are only looked up).
  tbb::parallel_for(size_t(0), jobs.size(), [&](size_t j) {
    Job& job = jobs[j];
    if (job.answer.what != RefKind::texture || !job.answer.message.empty()) return;
    job.image = texture(files.at(job.url).file, limits.max_texture_size, job.answer.message);
  });
  uint64_t payload = 0;
  for (Job& job : jobs) {
    Reference& a = job.answer;
    ClientRecord& rec = records[job.record];
    if (a.message.empty()) {
      if (auto* b = std::get_if<SetBufferRef>(&rec)) {
        const std::vector<uint8_t>& bytes = *files.at(job.url).file.bytes;
        const uint32_t size = source_size(b->source), elem = b->components * size;
        const uint32_t stride = b->byte_stride ? b->byte_stride : elem;
        const uint64_t count = b->value_count / b->components;
        const uint64_t end = count ? b->byte_offset + (count - 1) * stride + elem : b->byte_offset;
        if (b->byte_offset > bytes.size() || end > bytes.size()) {
          a.message = "the file holds " + std::to_string(bytes.size()) + " bytes; the buffer reads up to byte " +
                      std::to_string(b->byte_offset > bytes.size() ? b->byte_offset : end);
        } else if (uint64_t(b->value_count) * 4 > limits.max_message_payload_bytes - payload) {
          a.message = "the message's references exceed the limit of " +
                      std::to_string(limits.max_message_payload_bytes) + " bytes";
        } else {
          SetBuffer out;
          out.id = b->id;
          out.buffer.type = b->type;
          out.buffer.components = b->components;
          const uint8_t* src = bytes.data() + b->byte_offset;
          if (b->type == Buffer::Type::f32) {
            out.buffer.f.resize(b->value_count);
            if (stride == elem)
              std::memcpy(out.buffer.f.data(), src, size_t(b->value_count) * 4);
            else
              for (uint64_t k = 0; k < count; ++k)
                std::memcpy(&out.buffer.f[k * b->components], src + k * stride, elem);
          } else {
            out.buffer.u.resize(b->value_count);
            for (uint64_t k = 0; k < count; ++k)
              for (uint32_t c = 0; c < b->components; ++c) {
                const uint8_t* p = src + k * stride + c * size;
                uint32_t v = 0;
                if (size == 4) std::memcpy(&v, p, 4);
                else if (size == 2) v = uint32_t(p[0]) | uint32_t(p[1]) << 8;
                else v = p[0];
                out.buffer.u[k * b->components + c] = v;
              }
          }
          payload += uint64_t(b->value_count) * 4;
          a.ok = true;
          a.bytes = uint64_t(b->value_count) * 4;
          rec = std::move(out);
        }
      } else if (auto* t = std::get_if<SetTextureRef>(&rec)) {
        const uint64_t bytes = job.image->rgba.size();
        if (bytes > limits.max_message_payload_bytes - payload) {
          a.message = "the message's references exceed the limit of " +
                      std::to_string(limits.max_message_payload_bytes) + " bytes";
        } else {
          SetTexture out;
          out.id = t->id;
          out.texture.width = job.image->width;
          out.texture.height = job.image->height;
          // The cached image's bytes, shared (not copied) for as long as the texture holds them.
          out.texture.rgba = SharedBytes(std::shared_ptr<const std::vector<uint8_t>>(job.image, &job.image->rgba));
          out.texture.sampler = t->sampler;
          out.texture.srgb = t->srgb;
          payload += bytes;
          a.ok = true;
          a.bytes = bytes;
          rec = std::move(out);
        }
      }
    }
    if (!a.ok) a.message = std::string(kind_name(a.what)) + " " + std::to_string(a.id) + " (" + job.url + "): " + a.message;
    answers.push_back(std::move(a));
  }
}

}  // namespace tessera
