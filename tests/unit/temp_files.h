#pragma once
// Test files on disk: a temporary folder that removes itself, and a one-triangle glTF buffer.
#include <cstdint>
#include <cstdlib>
#include <fstream>
#include <stdexcept>
#include <string>

#include <stdlib.h>

namespace tessera::test {

struct TempDir {
  std::string path;
  explicit TempDir(const std::string& prefix = "tessera") {
    std::string tmpl = "/tmp/" + prefix + "-XXXXXX";
    char* p = mkdtemp(tmpl.data());
    if (!p) throw std::runtime_error("mkdtemp failed");
    path = p;
  }
  ~TempDir() { std::system(("rm -rf '" + path + "'").c_str()); }
  TempDir(const TempDir&) = delete;
  TempDir& operator=(const TempDir&) = delete;
  std::string write(const std::string& name, const std::string& data) const {
    std::string p = path + "/" + name;
    std::ofstream(p, std::ios::binary) << data;
    return p;
  }
};

// One triangle in tri.bin: 36 bytes of float3 positions, 6 of uint16 indices, 2 of padding.
inline std::string tri_bin() {
  float pos[9] = {0, 0, 0, 1, 0, 0, 0, 1, 0};
  uint16_t idx[4] = {0, 1, 2, 0};
  std::string s(reinterpret_cast<const char*>(pos), sizeof(pos));
  s.append(reinterpret_cast<const char*>(idx), sizeof(idx));
  return s;
}

}  // namespace tessera::test
