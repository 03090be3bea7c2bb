#pragma once
// zlib-format deflate (RFC 1950: 2-byte header 78 xx, deflate data, Adler-32), which is what
// browsers' CompressionStream('deflate') produces. Inflation has a hard output limit so a
// small "bomb" cannot make us allocate more than the caller allows.
#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

namespace tessera {

// Inflates a complete zlib stream into `out` (replaced). Never holds more than `max_output`
// bytes of output: the output grows geometrically up to the limit, and a stream that would
// produce more is rejected ("inflated size exceeds the limit of N bytes"). Also rejected:
// corrupt data, a truncated stream, bytes after the end of the stream. Returns false and sets
// `error` on failure.
bool inflate_zlib(const uint8_t* data, size_t size, size_t max_output, std::vector<uint8_t>& out,
                  std::string& error);

// Inflates a complete zlib stream whose inflated size is known up front into `out`, which
// holds exactly `expected` bytes: anything else (fewer, more, corrupt, truncated, trailing
// bytes) is an error. Allocates nothing beyond zlib's own state.
bool inflate_zlib_exact(const uint8_t* data, size_t size, uint8_t* out, size_t expected, std::string& error);

// Deflates into the zlib format (level 0..9, 6 = zlib's default, as CompressionStream).
std::vector<uint8_t> deflate_zlib(const uint8_t* data, size_t size, int level = 6);

}  // namespace tessera
