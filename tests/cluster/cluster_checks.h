#pragma once
// What several cluster tests check the same way: a master's frame against the direct render, a
// process's log tail for the failure message, and a CAF peer as any program could be.
#include <catch2/catch.hpp>

#include <string>
#include <vector>

#include <caf/all.hpp>
#include <caf/io/all.hpp>

#include "actors/cluster_protocol.h"
#include "actors/node.h"
#include "tests/e2e/node_fixture.h"
#include "tests/e2e/process.h"

namespace tessera::test {

inline std::string tail(const std::string& s, size_t n = 4000) { return s.substr(s.size() > n ? s.size() - n : 0); }

// Requests frame k of the pavilion's camera loop at w x h (the session's resolution) and checks
// it against the direct render (PSNR >= 30 dB).
inline void check_frame(ProtoClient& c, size_t k, uint32_t number, Process& master, int w = 240, int h = 136) {
  auto f = c.render(pavilion_loop().camera(k), number);
  INFO("master stderr tail: " << tail(master.err()));
  REQUIRE(f);
  CHECK(f->frame == number);
  REQUIRE(f->encoding == protocol::FrameEncoding::jpeg);
  const double psnr =
      compare(decode_jpeg(f->payload), render_direct(pavilion().scene, pavilion_loop().camera(k), w, h, 0, 0)).psnr;
  INFO("frame " << number << " PSNR " << psnr);
  CHECK(psnr >= 30.0);
}

// A CAF peer as any program could be: the nodes' message types and application identifier (CAF
// refuses other identifiers), the plain middleman.
struct PeerConfig : caf::actor_system_config {
  PeerConfig() {
    register_message_types(*this);
    load<caf::io::middleman>();
    set("middleman.app-identifiers", std::vector<std::string>{kCafAppIdentifier});
    set("scheduler.max-threads", size_t{2});
    set("logger.verbosity", caf::atom("quiet"));
  }
};

}  // namespace tessera::test
