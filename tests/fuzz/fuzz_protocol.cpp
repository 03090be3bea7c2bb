// libFuzzer target for the client protocol decoder (built with clang by run_fuzz.sh).
//
// Per input: decode as a client message and as a server message; a decoded client message
// is applied to a fresh scene, re-encoded, and the re-encoding must decode again to the same
// number of records (the encoders and decoders agree on everything the decoder accepts).
#include <cstdint>
#include <cstdlib>
#include <cstdio>

#include "protocol/protocol.h"
#include "update/scene_update.h"

using namespace tessera;
using namespace tessera::protocol;

namespace {
Limits fuzz_limits() {
  Limits lim;
  lim.max_message_bytes = 1 << 20;
  lim.max_message_payload_bytes = 16 << 20;  // keeps declared sizes within the fuzzer's RSS limit
  lim.max_buffer_bytes = 8 << 20;
  lim.max_client_bytes = 16 << 20;
  lim.max_texture_size = 1024;
  lim.max_triangles = 1 << 20;
  return lim;
}
}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  static const Limits lim = fuzz_limits();
  auto client = decode_client(data, size, lim);
  if (client.ok()) {
    // Textures arrive decoded: re-encode them raw.
    std::vector<ClientRecord> again = client.value();
    for (auto& r : again)
      if (auto* t = std::get_if<SetTexture>(&r)) t->format = TextureFormat::rgba8;
    auto bytes = encode(again);
    auto back = decode_client(bytes.data(), bytes.size(), lim);
    if (!back.ok() || back.value().size() != again.size()) {
      std::fprintf(stderr, "re-encoded message does not decode: %s\n", back.ok() ? "count" : back.error().message.c_str());
      std::abort();
    }
    Scene scene;
    (void)check_session_order(false, client.value());
    for (auto& r : client.value()) (void)apply(scene, std::move(r), lim);
    (void)scene.triangle_count();
    for (auto& [id, m] : scene.meshes()) (void)scene.validate_mesh(m.value);
  } else if (client.error().message.empty()) {
    std::abort();  // every error carries a message
  }
  auto server = decode_server(data, size, lim);
  if (server.ok()) {
    auto bytes = encode(server.value());
    auto back = decode_server(bytes.data(), bytes.size(), lim);
    if (!back.ok()) std::abort();
  }
  return 0;
}
