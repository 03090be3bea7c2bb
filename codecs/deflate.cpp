#include "codecs/deflate.h"

#include <zlib.h>

#include <algorithm>
#include <limits>

namespace tessera {

namespace {

// Owns a z_stream set up for zlib-format inflation.
struct Inflater {
  z_stream zs{};
  bool ok = false;
  Inflater() { ok = inflateInit2(&zs, 15) == Z_OK; }
  ~Inflater() {
    if (ok) inflateEnd(&zs);
  }
};

std::string zerror(int rc, const z_stream& zs) {
  std::string what = zs.msg ? zs.msg : "";
  switch (rc) {
    case Z_DATA_ERROR: return "deflate: corrupt data" + (what.empty() ? "" : " (" + what + ")");
    case Z_MEM_ERROR: return "deflate: out of memory";
    case Z_NEED_DICT: return "deflate: stream needs a preset dictionary (unsupported)";
    default: return "deflate: zlib error " + std::to_string(rc) + (what.empty() ? "" : " (" + what + ")");
  }
}

// Feeds all input (in chunks that fit zlib's 32-bit counters) and inflates into
// [dst, dst + room). Returns the zlib code of the last call.
constexpr size_t kChunk = std::numeric_limits<uInt>::max();

}  // namespace

bool inflate_zlib(const uint8_t* data, size_t size, size_t max_output, std::vector<uint8_t>& out,
                  std::string& error) {
  out.clear();
  Inflater inf;
  if (!inf.ok) {
    error = "deflate: inflateInit failed";
    return false;
  }
  z_stream& zs = inf.zs;
  size_t in_left = size;
  const uint8_t* in = data;
  size_t produced = 0;
  for (;;) {
    if (zs.avail_in == 0 && in_left > 0) {
      size_t n = std::min(in_left, kChunk);
      zs.next_in = const_cast<Bytef*>(in);
      zs.avail_in = uInt(n);
      in += n;
      in_left -= n;
    }
    if (produced == out.size()) {
      if (out.size() >= max_output) {
        // At the limit: any further output byte means the stream is too large.
        uint8_t probe;
        zs.next_out = &probe;
        zs.avail_out = 1;
        int rc = inflate(&zs, Z_NO_FLUSH);
        if (zs.avail_out == 0) {
          error = "deflate: inflated size exceeds the limit of " + std::to_string(max_output) + " bytes";
          out.clear();
          return false;
        }
        if (rc == Z_STREAM_END) break;
        if (rc != Z_OK && rc != Z_BUF_ERROR) {
          error = zerror(rc, zs);
          out.clear();
          return false;
        }
        if (zs.avail_in == 0 && in_left == 0) {
          error = "deflate: truncated stream";
          out.clear();
          return false;
        }
        continue;
      }
      size_t grow = std::max<size_t>(size_t(4096), out.size());
      out.resize(std::min(max_output, out.size() + std::min(grow, kChunk)));
    }
    zs.next_out = out.data() + produced;
    zs.avail_out = uInt(std::min(out.size() - produced, kChunk));
    uInt before = zs.avail_out;
    int rc = inflate(&zs, Z_NO_FLUSH);
    produced += before - zs.avail_out;
    if (rc == Z_STREAM_END) break;
    if (rc == Z_BUF_ERROR && zs.avail_in == 0 && in_left == 0) {
      error = "deflate: truncated stream";
      out.clear();
      return false;
    }
    if (rc != Z_OK && rc != Z_BUF_ERROR) {
      error = zerror(rc, zs);
      out.clear();
      return false;
    }
    if (rc == Z_OK && zs.avail_in == 0 && in_left == 0 && zs.avail_out != 0) {
      error = "deflate: truncated stream";
      out.clear();
      return false;
    }
  }
  if (zs.avail_in != 0 || in_left != 0) {
    error = "deflate: " + std::to_string(zs.avail_in + in_left) + " bytes after the end of the stream";
    out.clear();
    return false;
  }
  out.resize(produced);
  return true;
}

bool inflate_zlib_exact(const uint8_t* data, size_t size, uint8_t* out, size_t expected, std::string& error) {
  Inflater inf;
  if (!inf.ok) {
    error = "deflate: inflateInit failed";
    return false;
  }
  z_stream& zs = inf.zs;
  size_t in_left = size, out_left = expected;
  const uint8_t* in = data;
  uint8_t* dst = out;
  uint8_t probe;
  for (;;) {
    if (zs.avail_in == 0 && in_left > 0) {
      size_t n = std::min(in_left, kChunk);
      zs.next_in = const_cast<Bytef*>(in);
      zs.avail_in = uInt(n);
      in += n;
      in_left -= n;
    }
    bool probing = out_left == 0;
    if (probing) {
      zs.next_out = &probe;
      zs.avail_out = 1;
    } else {
      zs.next_out = dst;
      zs.avail_out = uInt(std::min(out_left, kChunk));
    }
    uInt before = zs.avail_out;
    int rc = inflate(&zs, Z_NO_FLUSH);
    size_t got = before - zs.avail_out;
    if (probing && got) {
      error = "deflate: inflated size exceeds the declared " + std::to_string(expected) + " bytes";
      return false;
    }
    dst += got;
    out_left -= probing ? 0 : got;
    if (rc == Z_STREAM_END) break;
    if (rc != Z_OK && rc != Z_BUF_ERROR) {
      error = zerror(rc, zs);
      return false;
    }
    if (zs.avail_in == 0 && in_left == 0 && (rc == Z_BUF_ERROR || zs.avail_out != 0)) {
      error = "deflate: truncated stream";
      return false;
    }
  }
  if (out_left != 0) {
    error = "deflate: inflated " + std::to_string(expected - out_left) + " bytes, declared " +
            std::to_string(expected);
    return false;
  }
  if (zs.avail_in != 0 || in_left != 0) {
    error = "deflate: " + std::to_string(zs.avail_in + in_left) + " bytes after the end of the stream";
    return false;
  }
  return true;
}

std::vector<uint8_t> deflate_zlib(const uint8_t* data, size_t size, int level) {
  uLongf bound = compressBound(uLong(size));
  std::vector<uint8_t> out(bound);
  if (compress2(out.data(), &bound, data, uLong(size), std::clamp(level, 0, 9)) != Z_OK) return {};
  out.resize(bound);
  return out;
}

}  // namespace tessera
