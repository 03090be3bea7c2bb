#pragma once
// One `tessera serve` process of a cluster test (the built binary, TESSERA_BINARY): started on
// free ports, its first stdout line names its endpoints. Shared by the cluster tests.
#include <catch2/catch.hpp>

#include <memory>
#include <string>
#include <vector>

#include "tests/e2e/process.h"

namespace tessera::test {

// The string value of "key": "value" in a JSON line ("" when absent).
inline std::string json_field(const std::string& line, const std::string& key) {
  auto at = line.find("\"" + key + "\": \"");
  if (at == std::string::npos) return {};
  at += key.size() + 5;
  return line.substr(at, line.find('"', at) - at);
}

struct ServeNode {
  std::unique_ptr<Process> p;
  uint16_t http = 0, cluster = 0;

  // One render thread, lost children retried every 200 ms, tasks failed after 3 s; `extra` after.
  explicit ServeNode(std::vector<std::string> extra) {
    std::vector<std::string> a{TESSERA_BINARY, "serve", "--threads", "1", "--tessera.reconnect-ms=200",
                               "--tessera.task-timeout-ms=3000", "--web-root", "web"};
    a.insert(a.end(), extra.begin(), extra.end());
    p = std::make_unique<Process>(a);
    auto line = p->first_line(30000);
    INFO("stderr: " << p->err());
    REQUIRE(line);
    std::string url = json_field(*line, "listening"), cl = json_field(*line, "cluster");
    if (!url.empty()) http = uint16_t(std::stoi(url.substr(url.rfind(':') + 1)));
    if (!cl.empty()) cluster = uint16_t(std::stoi(cl.substr(cl.rfind(':') + 1)));
  }
  std::string addr() const { return "127.0.0.1:" + std::to_string(cluster); }
};

}  // namespace tessera::test
