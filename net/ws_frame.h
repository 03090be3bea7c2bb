#pragma once
// WebSocket framing for clients that speak raw TCP to a node: tessera soak's never-reading
// client and the tests' slow or never-reading clients (everything else goes through websocketpp).
#include <cstddef>
#include <cstdint>
#include <vector>

namespace tessera {

// One binary WebSocket message as a client must send it (RFC 6455: masked).
inline std::vector<uint8_t> masked_ws_frame(const std::vector<uint8_t>& payload, const uint8_t (&mask)[4]) {
  std::vector<uint8_t> f{0x82};
  const size_t n = payload.size();
  if (n < 126) {
    f.push_back(uint8_t(0x80 | n));
  } else if (n < 65536) {
    f.push_back(0x80 | 126);
    f.push_back(uint8_t(n >> 8));
    f.push_back(uint8_t(n));
  } else {
    f.push_back(0x80 | 127);
    for (int s = 56; s >= 0; s -= 8) f.push_back(uint8_t(uint64_t(n) >> s));
  }
  f.insert(f.end(), mask, mask + 4);
  for (size_t i = 0; i < n; ++i) f.push_back(payload[i] ^ mask[i % 4]);
  return f;
}

}  // namespace tessera
