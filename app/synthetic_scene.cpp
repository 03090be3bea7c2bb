#include "app/synthetic_scene.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <stdexcept>
#include <vector>

#include <tbb/parallel_for.h>

#include "codecs/jpeg.h"

namespace tessera::app {
namespace {

constexpr double kPi = 3.14159265358979323846;

// A small deterministic generator (splitmix64): the same seed gives the same scene everywhere.
struct Rng {
  uint64_t s;
  uint64_t next() {
    uint64_t z = (s += 0x9E3779B97F4A7C15ull);
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
    return z ^ (z >> 31);
  }
  double uniform(double lo, double hi) { return lo + (hi - lo) * double(next() >> 11) * (1.0 / 9007199254740992.0); }
  int integer(int lo, int hi) { return lo + int(next() % uint64_t(hi - lo + 1)); }
};

uint32_t hash2(uint32_t x, uint32_t y, uint32_t seed) {
  uint32_t h = x * 0x8DA6B343u ^ y * 0xD8163841u ^ seed * 0xCB1AB31Fu;
  h ^= h >> 13;
  h *= 0x5BD1E995u;
  return h ^ (h >> 15);
}

// Value noise in 0..1 at (x, y) over a lattice of `cell` pixels that wraps every `period` cells
// (so the texture tiles).
float value_noise(int x, int y, int cell, int period, uint32_t seed) {
  const int cx = x / cell, cy = y / cell;
  const float fx = float(x % cell) / float(cell), fy = float(y % cell) / float(cell);
  auto v = [&](int i, int j) { return float(hash2(uint32_t(i % period), uint32_t(j % period), seed) & 0xFFFF) / 65535.0f; };
  const float sx = fx * fx * (3 - 2 * fx), sy = fy * fy * (3 - 2 * fy);
  const float a = v(cx, cy) + (v(cx + 1, cy) - v(cx, cy)) * sx;
  const float b = v(cx, cy + 1) + (v(cx + 1, cy + 1) - v(cx, cy + 1)) * sx;
  return a + (b - a) * sy;
}

std::vector<uint8_t> texture_jpeg(int index, int size, int quality, uint32_t seed) {
  Rng rng{seed * 7919ull + uint64_t(index)};
  const float base[3] = {float(rng.uniform(0.2, 0.9)), float(rng.uniform(0.2, 0.9)), float(rng.uniform(0.2, 0.9))};
  std::vector<uint8_t> rgba(size_t(size) * size_t(size) * 4);
  const int cells[3] = {std::max(1, size / 4), std::max(1, size / 32), std::max(1, size / 128)};
  for (int y = 0; y < size; ++y)
    for (int x = 0; x < size; ++x) {
      float n = 0.5f * value_noise(x, y, cells[0], std::max(1, size / cells[0]), seed + uint32_t(index) * 3) +
                0.3f * value_noise(x, y, cells[1], std::max(1, size / cells[1]), seed + uint32_t(index) * 3 + 1) +
                0.2f * value_noise(x, y, cells[2], std::max(1, size / cells[2]), seed + uint32_t(index) * 3 + 2);
      // Grain: per-pixel noise, so that a JPEG weighs about what a photographed texture does
      // (about 0.4 bytes a pixel at quality 90) and the scene about San Miguel's 150 MB.
      n += 0.25f * (float(hash2(uint32_t(x), uint32_t(y), seed ^ uint32_t(index)) & 0xFFFF) / 65535.0f - 0.5f);
      uint8_t* p = &rgba[(size_t(y) * size_t(size) + size_t(x)) * 4];
      for (int c = 0; c < 3; ++c) p[c] = uint8_t(std::clamp(255.0f * base[c] * (0.4f + 0.9f * n), 0.0f, 255.0f));
      p[3] = 255;
    }
  JpegEncoder enc;
  std::vector<uint8_t> out;
  std::string error;
  if (!enc.encode(rgba.data(), size, size, quality, out, error)) throw std::runtime_error("texture " + std::to_string(index) + ": " + error);
  return out;
}

struct MeshData {
  int grid = 0;
  size_t positions = 0, normals = 0, texcoords = 0, indices = 0;  // byte offsets in the .bin
  float min[3], max[3];
  uint64_t triangles() const { return 2ull * uint64_t(grid) * uint64_t(grid); }
};

// A bumpy grid of 2 g^2 triangles in the XZ plane, appended to `bin`.
MeshData append_mesh(std::vector<uint8_t>& bin, Rng& rng) {
  MeshData m;
  const int g = m.grid = rng.integer(8, 48);
  const double s = rng.uniform(0.5, 3.0), amp = rng.uniform(0.05, 0.6) * s;
  const double fa = rng.integer(1, 4), fb = rng.integer(1, 4), rep = rng.integer(1, 4);
  const int nv = (g + 1) * (g + 1);
  std::vector<float> pos, nrm, uv;
  pos.reserve(size_t(nv) * 3);
  nrm.reserve(size_t(nv) * 3);
  uv.reserve(size_t(nv) * 2);
  for (int k = 0; k < 3; ++k) m.min[k] = INFINITY, m.max[k] = -INFINITY;
  for (int j = 0; j <= g; ++j)
    for (int i = 0; i <= g; ++i) {
      const double u = double(i) / g, v = double(j) / g;
      const double su = std::sin(2 * kPi * fa * u), cu = std::cos(2 * kPi * fa * u);
      const double sv = std::sin(2 * kPi * fb * v), cv = std::cos(2 * kPi * fb * v);
      const double h = amp * su * cv;
      const double dhdx = amp * 2 * kPi * fa * cu * cv / s, dhdz = -amp * 2 * kPi * fb * su * sv / s;
      const float p[3] = {float(s * (u - 0.5)), float(h), float(s * (v - 0.5))};
      const double len = std::sqrt(dhdx * dhdx + 1 + dhdz * dhdz);
      pos.insert(pos.end(), p, p + 3);
      nrm.insert(nrm.end(), {float(-dhdx / len), float(1 / len), float(-dhdz / len)});
      uv.insert(uv.end(), {float(u * rep), float(v * rep)});
      for (int k = 0; k < 3; ++k) m.min[k] = std::min(m.min[k], p[k]), m.max[k] = std::max(m.max[k], p[k]);
    }
  std::vector<uint32_t> idx;
  idx.reserve(size_t(g) * size_t(g) * 6);
  for (int j = 0; j < g; ++j)
    for (int i = 0; i < g; ++i) {
      const uint32_t a = uint32_t(j * (g + 1) + i), b = a + 1, c = a + uint32_t(g) + 1, d = c + 1;
      idx.insert(idx.end(), {a, c, b, b, c, d});
    }
  auto append = [&](const void* data, size_t bytes) {
    const size_t at = bin.size();  // every part is a multiple of 4 bytes: offsets stay aligned
    bin.resize(at + bytes);
    std::copy_n(static_cast<const uint8_t*>(data), bytes, bin.data() + at);
    return at;
  };
  m.positions = append(pos.data(), pos.size() * 4);
  m.normals = append(nrm.data(), nrm.size() * 4);
  m.texcoords = append(uv.data(), uv.size() * 4);
  m.indices = append(idx.data(), idx.size() * 4);
  return m;
}

std::string num(double v) {
  char b[32];
  std::snprintf(b, sizeof(b), "%.7g", v);
  return b;
}

void write_file(const std::filesystem::path& p, const void* data, size_t bytes) {
  std::ofstream f(p, std::ios::binary | std::ios::trunc);
  if (!f || !f.write(static_cast<const char*>(data), std::streamsize(bytes)) || !f.flush())
    throw std::runtime_error("cannot write " + p.string());
}

}  // namespace

SyntheticSceneFigures write_synthetic_scene(const std::string& folder, const SyntheticSceneSpec& spec) {
  if (spec.unique_triangles < 1 || spec.unique_triangles > 100'000'000)
    throw std::invalid_argument("unique triangles must be 1..100000000");
  if (spec.instanced_triangles < spec.unique_triangles || spec.instanced_triangles > 1'000'000'000)
    throw std::invalid_argument("instanced triangles must be at least the unique ones and at most 1000000000");
  if (spec.textures < 0 || spec.textures > 10000) throw std::invalid_argument("textures must be 0..10000");
  if (spec.texture_size < 8 || spec.texture_size > 8192) throw std::invalid_argument("texture size must be 8..8192");
  if (spec.jpeg_quality < 1 || spec.jpeg_quality > 100) throw std::invalid_argument("JPEG quality must be 1..100");
  namespace fs = std::filesystem;
  const fs::path dir(folder);
  fs::create_directories(dir / "textures");
  SyntheticSceneFigures out;

  // Geometry: unique meshes until the unique triangle count is reached.
  Rng rng{spec.seed};
  std::vector<uint8_t> bin;
  std::vector<MeshData> meshes;
  while (out.unique_triangles < spec.unique_triangles) {
    meshes.push_back(append_mesh(bin, rng));
    out.unique_triangles += meshes.back().triangles();
  }
  out.meshes = int(meshes.size());
  write_file(dir / "scene.bin", bin.data(), bin.size());
  out.bin_bytes = bin.size();

  // Textures, in parallel (each JPEG on its own).
  std::vector<uint64_t> tex_bytes(size_t(spec.textures), 0);
  tbb::parallel_for(0, spec.textures, [&](int t) {
    std::vector<uint8_t> jpeg = texture_jpeg(t, spec.texture_size, spec.jpeg_quality, spec.seed);
    char name[32];
    std::snprintf(name, sizeof(name), "t%03d.jpg", t);
    write_file(dir / "textures" / name, jpeg.data(), jpeg.size());
    tex_bytes[size_t(t)] = jpeg.size();
  });
  for (uint64_t b : tex_bytes) out.texture_bytes += b;
  out.textures = spec.textures;
  out.materials = std::max(1, spec.textures);

  // The scene: every mesh once on a courtyard floor of 3 m cells (on up to four storeys), then
  // instances of the first tenth of the meshes anywhere in it.
  const int cols = int(std::ceil(std::sqrt(double(meshes.size()))));
  const double side = 3.0 * cols;
  struct Node { int mesh; double t[3]; double yaw; double scale; };
  std::vector<Node> nodes;
  for (size_t k = 0; k < meshes.size(); ++k)
    nodes.push_back({int(k), {3.0 * double(k % size_t(cols)), 3.0 * double(rng.integer(0, 3)), 3.0 * double(k / size_t(cols))}, 0, 1});
  out.instanced_triangles = out.unique_triangles;
  const int instanced_set = std::max(1, int(meshes.size()) / 10);
  while (out.instanced_triangles < spec.instanced_triangles) {
    const int mesh = rng.integer(0, instanced_set - 1);
    nodes.push_back({mesh, {rng.uniform(0, side), rng.uniform(0, 12), rng.uniform(0, side)}, rng.uniform(0, 2 * kPi), rng.uniform(0.5, 1.5)});
    out.instanced_triangles += meshes[size_t(mesh)].triangles();
  }

  std::ostringstream j;
  j << "{\"asset\":{\"version\":\"2.0\",\"generator\":\"tessera make-scene (seed " << spec.seed << ")\"},"
    << "\"extensionsUsed\":[\"KHR_lights_punctual\"],"
    << "\"extensions\":{\"KHR_lights_punctual\":{\"lights\":[{\"type\":\"directional\",\"color\":[1,0.95,0.85],\"intensity\":3}]}},"
    << "\"buffers\":[{\"uri\":\"scene.bin\",\"byteLength\":" << bin.size() << "}],";
  j << "\"bufferViews\":[";
  for (size_t k = 0; k < meshes.size(); ++k) {
    const MeshData& m = meshes[k];
    const uint64_t nv = uint64_t(m.grid + 1) * uint64_t(m.grid + 1);
    j << (k ? "," : "") << "{\"buffer\":0,\"byteOffset\":" << m.positions << ",\"byteLength\":" << nv * 12 << ",\"target\":34962},"
      << "{\"buffer\":0,\"byteOffset\":" << m.normals << ",\"byteLength\":" << nv * 12 << ",\"target\":34962},"
      << "{\"buffer\":0,\"byteOffset\":" << m.texcoords << ",\"byteLength\":" << nv * 8 << ",\"target\":34962},"
      << "{\"buffer\":0,\"byteOffset\":" << m.indices << ",\"byteLength\":" << m.triangles() * 12 << ",\"target\":34963}";
  }
  j << "],\"accessors\":[";
  for (size_t k = 0; k < meshes.size(); ++k) {
    const MeshData& m = meshes[k];
    const uint64_t nv = uint64_t(m.grid + 1) * uint64_t(m.grid + 1);
    const size_t v = k * 4;
    j << (k ? "," : "") << "{\"bufferView\":" << v << ",\"componentType\":5126,\"count\":" << nv << ",\"type\":\"VEC3\",\"min\":["
      << num(m.min[0]) << "," << num(m.min[1]) << "," << num(m.min[2]) << "],\"max\":[" << num(m.max[0]) << "," << num(m.max[1]) << ","
      << num(m.max[2]) << "]},"
      << "{\"bufferView\":" << v + 1 << ",\"componentType\":5126,\"count\":" << nv << ",\"type\":\"VEC3\"},"
      << "{\"bufferView\":" << v + 2 << ",\"componentType\":5126,\"count\":" << nv << ",\"type\":\"VEC2\"},"
      << "{\"bufferView\":" << v + 3 << ",\"componentType\":5125,\"count\":" << m.triangles() * 3 << ",\"type\":\"SCALAR\"}";
  }
  j << "],\"meshes\":[";
  for (size_t k = 0; k < meshes.size(); ++k)
    j << (k ? "," : "") << "{\"primitives\":[{\"attributes\":{\"POSITION\":" << k * 4 << ",\"NORMAL\":" << k * 4 + 1
      << ",\"TEXCOORD_0\":" << k * 4 + 2 << "},\"indices\":" << k * 4 + 3 << ",\"material\":" << k % size_t(out.materials) << "}]}";
  j << "],\"materials\":[";
  for (int m = 0; m < out.materials; ++m) {
    j << (m ? "," : "") << "{\"pbrMetallicRoughness\":{";
    if (spec.textures > 0) j << "\"baseColorTexture\":{\"index\":" << m << "},";
    j << "\"baseColorFactor\":[1,1,1,1],\"metallicFactor\":0,\"roughnessFactor\":0.8}}";
  }
  j << "],\"samplers\":[{\"magFilter\":9729,\"minFilter\":9987,\"wrapS\":10497,\"wrapT\":10497}],\"images\":[";
  for (int t = 0; t < spec.textures; ++t) {
    char name[48];
    std::snprintf(name, sizeof(name), "textures/t%03d.jpg", t);
    j << (t ? "," : "") << "{\"uri\":\"" << name << "\"}";
  }
  j << "],\"textures\":[";
  for (int t = 0; t < spec.textures; ++t) j << (t ? "," : "") << "{\"sampler\":0,\"source\":" << t << "}";
  // The camera looks over the courtyard from above its near edge, 35 degrees down; the sun
  // shines from 60 degrees up.
  const double pitch = -35 * kPi / 180, sun = -60 * kPi / 180;
  j << "],\"cameras\":[{\"type\":\"perspective\",\"perspective\":{\"yfov\":0.9,\"znear\":0.1,\"zfar\":" << num(side * 4) << "}}],";
  j << "\"nodes\":[";
  for (size_t k = 0; k < nodes.size(); ++k) {
    const Node& n = nodes[k];
    j << (k ? "," : "") << "{\"mesh\":" << n.mesh << ",\"translation\":[" << num(n.t[0]) << "," << num(n.t[1]) << "," << num(n.t[2]) << "]";
    if (n.yaw != 0) j << ",\"rotation\":[0," << num(std::sin(n.yaw / 2)) << ",0," << num(std::cos(n.yaw / 2)) << "]";
    if (n.scale != 1) j << ",\"scale\":[" << num(n.scale) << "," << num(n.scale) << "," << num(n.scale) << "]";
    j << "}";
  }
  j << ",{\"camera\":0,\"translation\":[" << num(side / 2) << "," << num(std::max(8.0, side * 0.35)) << "," << num(side * 1.15)
    << "],\"rotation\":[" << num(std::sin(pitch / 2)) << ",0,0," << num(std::cos(pitch / 2)) << "]}";
  j << ",{\"extensions\":{\"KHR_lights_punctual\":{\"light\":0}},\"rotation\":[" << num(std::sin(sun / 2)) << ",0,0,"
    << num(std::cos(sun / 2)) << "]}";
  j << "],\"scenes\":[{\"nodes\":[";
  for (size_t k = 0; k < nodes.size() + 2; ++k) j << (k ? "," : "") << k;
  j << "]}],\"scene\":0}\n";
  out.nodes = int(nodes.size());
  // A camera loop for tessera bench: one turn around the courtyard in 120 frames, from where
  // the scene's camera stands, looking at the courtyard's centre.
  {
    std::ostringstream loop;
    const double cx = side / 2, cz = side / 2, r = side * 0.65, h = std::max(8.0, side * 0.35);
    loop << "{\"fovY_deg\": 50, \"frames\": [";
    for (int f = 0; f < 120; ++f) {
      const double a = 2 * kPi * f / 120;
      loop << (f ? "," : "") << "\n {\"eye\": [" << num(cx + r * std::sin(a)) << ", " << num(h) << ", " << num(cz + r * std::cos(a))
           << "], \"target\": [" << num(cx) << ", 2, " << num(cz) << "], \"up\": [0, 1, 0]}";
    }
    loop << "]}\n";
    const std::string text = loop.str();
    write_file(dir / "camera-loop.json", text.data(), text.size());
  }
  const std::string json = j.str();
  write_file(dir / "scene.gltf", json.data(), json.size());
  out.json_bytes = json.size();
  return out;
}

}  // namespace tessera::app
