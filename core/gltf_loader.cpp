#include "core/gltf_loader.h"

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <limits>
#include <map>
#include <set>
#include <stdexcept>
#include <utility>

#define TINYGLTF_IMPLEMENTATION
#define TINYGLTF_NO_STB_IMAGE_WRITE
#define TINYGLTF_NO_INCLUDE_STB_IMAGE_WRITE
#if defined(__GNUC__)
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wmissing-field-initializers"
#pragma GCC diagnostic ignored "-Wsign-compare"
#pragma GCC diagnostic ignored "-Wunused-function"
#pragma GCC diagnostic ignored "-Wunused-variable"
#pragma GCC diagnostic ignored "-Wunused-but-set-variable"
#pragma GCC diagnostic ignored "-Wimplicit-fallthrough"
#pragma GCC diagnostic ignored "-Wmaybe-uninitialized"
#pragma GCC diagnostic ignored "-Wpedantic"
#endif
#include <tiny_gltf.h>
#include <tbb/parallel_for.h>
#if defined(__GNUC__)
#pragma GCC diagnostic pop
#endif

#include "core/image.h"
#include "core/validate.h"

namespace tessera {
namespace {

struct LoadError : std::runtime_error {
  using std::runtime_error::runtime_error;
};

// Reads accessor `index` as `comps` floats per element (converting normalized integers).
// An accessor without a bufferView is all zeros before its sparse substitutions; it may hold
// at most this many elements, so that a count alone cannot allocate gigabytes. Accessors with
// a bufferView are bounded by their (checked) bufferView instead.
constexpr size_t kMaxZeroAccessor = size_t(1) << 24;

// Where accessor `acc`'s `count` elements of `elem` bytes lie: checked against its bufferView
// and buffer before anything is allocated (check_buffer_views has checked every bufferView
// against its buffer). Returns the first element's offset in the buffer and the stride.
struct AccessorSpan {
  size_t start = 0, stride = 0;
};
AccessorSpan accessor_span(const tinygltf::Model& m, const tinygltf::Accessor& acc, size_t elem, const std::string& what) {
  if (acc.bufferView < 0 || size_t(acc.bufferView) >= m.bufferViews.size()) throw LoadError(what + ": bufferView out of range");
  const auto& bv = m.bufferViews[acc.bufferView];
  const size_t stride = bv.byteStride ? bv.byteStride : elem;
  // In divisions, not products: a count or stride from the file cannot overflow the check.
  const size_t len = bv.byteLength;
  const bool fits = acc.count == 0 || (acc.byteOffset <= len && elem <= len - acc.byteOffset && stride > 0 &&
                                       (acc.count - 1) <= (len - acc.byteOffset - elem) / stride);
  if (!fits)
    throw LoadError(what + ": accessor of " + std::to_string(acc.count) + " elements (stride " + std::to_string(stride) +
                    ", byteOffset " + std::to_string(acc.byteOffset) + ") reads past the end of bufferView " +
                    std::to_string(acc.bufferView) + " (" + std::to_string(bv.byteLength) + " bytes)");
  return {bv.byteOffset + acc.byteOffset, stride};
}

// Every bufferView must lie inside its buffer: checked once, before any accessor is read.
void check_buffer_views(const tinygltf::Model& m, const std::string& path) {
  for (size_t i = 0; i < m.bufferViews.size(); ++i) {
    const auto& bv = m.bufferViews[i];
    if (bv.buffer < 0 || size_t(bv.buffer) >= m.buffers.size())
      throw LoadError(path + ": bufferView " + std::to_string(i) + " names buffer " + std::to_string(bv.buffer) +
                      ", which does not exist");
    const size_t size = m.buffers[bv.buffer].data.size();
    if (bv.byteOffset > size || bv.byteLength > size - bv.byteOffset)
      throw LoadError(path + ": bufferView " + std::to_string(i) + " (byteOffset " + std::to_string(bv.byteOffset) +
                      ", byteLength " + std::to_string(bv.byteLength) + ") exceeds buffer " + std::to_string(bv.buffer) +
                      " (" + std::to_string(size) + " bytes)");
  }
}

// An unsigned integer of `size` bytes (1, 2 or 4), little-endian as glTF stores it.
uint32_t read_uint(const unsigned char* p, size_t size) {
  if (size == 1) return p[0];
  if (size == 2) { uint16_t v; std::memcpy(&v, p, 2); return v; }
  uint32_t v; std::memcpy(&v, p, 4); return v;
}

// One component of a vertex attribute as a float (glTF 2.0, "Accessor Data Types", and
// KHR_mesh_quantization, which allows every integer type below for positions, normals and
// texture coordinates): a float as it is, an integer as its value, a normalized unsigned one
// over its maximum, a normalized signed one over its maximum and clamped at -1.
float component(const unsigned char* p, int type, bool normalized) {
  switch (type) {
    case TINYGLTF_COMPONENT_TYPE_FLOAT: { float v; std::memcpy(&v, p, 4); return v; }
    case TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE: return normalized ? p[0] / 255.0f : float(p[0]);
    case TINYGLTF_COMPONENT_TYPE_BYTE: {
      int8_t v; std::memcpy(&v, p, 1);
      return normalized ? std::fmax(v / 127.0f, -1.0f) : float(v);
    }
    case TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT: { uint16_t v; std::memcpy(&v, p, 2); return normalized ? v / 65535.0f : float(v); }
    case TINYGLTF_COMPONENT_TYPE_SHORT: {
      int16_t v; std::memcpy(&v, p, 2);
      return normalized ? std::fmax(v / 32767.0f, -1.0f) : float(v);
    }
    default: return 0.0f;  // not reached: read_floats checks the type first
  }
}

bool float_component_type(int type) {
  return type == TINYGLTF_COMPONENT_TYPE_FLOAT || type == TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE ||
         type == TINYGLTF_COMPONENT_TYPE_BYTE || type == TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT ||
         type == TINYGLTF_COMPONENT_TYPE_SHORT;
}

// A sparse accessor's substitutions (glTF 2.0, "Sparse Accessors"): `count` strictly increasing
// indices of `acc`'s elements and as many tightly packed elements of `elem` bytes that replace
// them. Calls put(element index, the replacement's bytes) for each, after checking that both
// arrays lie inside their bufferViews and that every index is below the accessor's count.
template <class Put>
void apply_sparse(const tinygltf::Model& m, const tinygltf::Accessor& acc, size_t elem, const std::string& what, Put put) {
  if (!acc.sparse.isSparse) return;
  const auto& sp = acc.sparse;
  if (sp.count < 1 || size_t(sp.count) > acc.count)
    throw LoadError(what + ": sparse accessor with " + std::to_string(sp.count) + " substitutions for " +
                    std::to_string(acc.count) + " elements");
  const int itype = sp.indices.componentType;
  const size_t isize = itype == TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE    ? 1
                       : itype == TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT ? 2
                       : itype == TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT   ? 4
                                                                         : 0;
  if (isize == 0) throw LoadError(what + ": sparse indices must be unsigned bytes, shorts or ints");
  const size_t n = size_t(sp.count);
  auto span = [&](int view, int offset, size_t size, const char* part) -> const unsigned char* {
    if (view < 0 || size_t(view) >= m.bufferViews.size() || offset < 0)
      throw LoadError(what + ": sparse " + part + " name no bufferView");
    const auto& bv = m.bufferViews[size_t(view)];
    // In divisions, not products: a count from the file cannot overflow the check.
    if (size_t(offset) > bv.byteLength || (bv.byteLength - size_t(offset)) / size < n)
      throw LoadError(what + ": sparse " + part + " read past the end of bufferView " + std::to_string(view));
    return m.buffers[size_t(bv.buffer)].data.data() + bv.byteOffset + size_t(offset);
  };
  const unsigned char* idx = span(sp.indices.bufferView, sp.indices.byteOffset, isize, "indices");
  const unsigned char* val = span(sp.values.bufferView, sp.values.byteOffset, elem, "values");
  uint64_t last = 0;
  for (size_t k = 0; k < n; ++k) {
    const uint32_t i = read_uint(idx + k * isize, isize);
    if (i >= acc.count || (k > 0 && i <= last))
      throw LoadError(what + ": sparse index " + std::to_string(i) + " out of range or not increasing");
    last = i;
    put(size_t(i), val + k * elem);
  }
}

std::vector<float> read_floats(const tinygltf::Model& m, int index, int comps, const std::string& what) {
  if (index < 0 || size_t(index) >= m.accessors.size()) throw LoadError(what + ": accessor index out of range");
  const auto& acc = m.accessors[index];
  int nc = tinygltf::GetNumComponentsInType(acc.type);
  if (nc != comps) throw LoadError(what + ": expected " + std::to_string(comps) + " components, got " + std::to_string(nc));
  if (!float_component_type(acc.componentType))
    throw LoadError(what + ": unsupported component type " + std::to_string(acc.componentType));
  const int type = acc.componentType;
  const size_t csize = size_t(tinygltf::GetComponentSizeInBytes(uint32_t(type)));
  std::vector<float> out;
  if (acc.bufferView < 0) {  // all zeros, unless sparse substitutions follow
    if (acc.count > kMaxZeroAccessor)
      throw LoadError(what + ": accessor without a bufferView has " + std::to_string(acc.count) + " elements (at most " +
                      std::to_string(kMaxZeroAccessor) + ")");
    out.assign(acc.count * comps, 0.0f);
  } else {
    const auto span = accessor_span(m, acc, csize * comps, what);
    const auto& buf = m.buffers[m.bufferViews[acc.bufferView].buffer].data;
    const size_t start = span.start, stride = span.stride;
    out.assign(acc.count * comps, 0.0f);
    for (size_t i = 0; i < acc.count; ++i) {
      const unsigned char* p = buf.data() + start + i * stride;
      for (int c = 0; c < comps; ++c) out[i * comps + c] = component(p + size_t(c) * csize, type, acc.normalized);
    }
  }
  apply_sparse(m, acc, csize * comps, what, [&](size_t i, const unsigned char* p) {
    for (int c = 0; c < comps; ++c) out[i * comps + c] = component(p + size_t(c) * csize, type, acc.normalized);
  });
  return out;
}

std::vector<uint32_t> read_indices(const tinygltf::Model& m, int index, const std::string& what) {
  if (index < 0 || size_t(index) >= m.accessors.size()) throw LoadError(what + ": index accessor out of range");
  const auto& acc = m.accessors[index];
  if (acc.type != TINYGLTF_TYPE_SCALAR || acc.bufferView < 0 || size_t(acc.bufferView) >= m.bufferViews.size())
    throw LoadError(what + ": indices must be a scalar accessor with a bufferView");
  int csize = tinygltf::GetComponentSizeInBytes(acc.componentType);
  if (csize != 1 && csize != 2 && csize != 4) throw LoadError(what + ": bad index component type");
  const auto span = accessor_span(m, acc, size_t(csize), what + " indices");
  const auto& buf = m.buffers[m.bufferViews[acc.bufferView].buffer].data;
  const size_t start = span.start, stride = span.stride;
  std::vector<uint32_t> out(acc.count);
  for (size_t i = 0; i < acc.count; ++i) {
    const unsigned char* p = buf.data() + start + i * stride;
    out[i] = read_uint(p, size_t(csize));
  }
  apply_sparse(m, acc, size_t(csize), what + " indices",
               [&](size_t i, const unsigned char* p) { out[i] = read_uint(p, size_t(csize)); });
  return out;
}

Mat4 node_local(const tinygltf::Node& n) {
  if (n.matrix.size() == 16) {
    Mat4 r;
    for (int i = 0; i < 16; ++i) r.m[i] = float(n.matrix[i]);
    return r;
  }
  Mat4 t, r, s;
  if (n.translation.size() == 3) t = Mat4::translate({float(n.translation[0]), float(n.translation[1]), float(n.translation[2])});
  if (n.rotation.size() == 4) {
    float x = float(n.rotation[0]), y = float(n.rotation[1]), z = float(n.rotation[2]), w = float(n.rotation[3]);
    r(0, 0) = 1 - 2 * (y * y + z * z); r(0, 1) = 2 * (x * y - z * w);     r(0, 2) = 2 * (x * z + y * w);
    r(1, 0) = 2 * (x * y + z * w);     r(1, 1) = 1 - 2 * (x * x + z * z); r(1, 2) = 2 * (y * z - x * w);
    r(2, 0) = 2 * (x * z - y * w);     r(2, 1) = 2 * (y * z + x * w);     r(2, 2) = 1 - 2 * (x * x + y * y);
  }
  if (n.scale.size() == 3) s = Mat4::scale({float(n.scale[0]), float(n.scale[1]), float(n.scale[2])});
  return t * r * s;
}

Vec3 vec3_of(const std::vector<double>& v, Vec3 fallback) {
  return v.size() >= 3 ? Vec3{float(v[0]), float(v[1]), float(v[2])} : fallback;
}

double number_or(const tinygltf::Value& obj, const char* key, double fallback) {
  if (!obj.IsObject() || !obj.Has(key)) return fallback;
  const auto& v = obj.Get(key);
  return v.IsNumber() ? v.GetNumberAsDouble() : fallback;
}

// A triangle strip or fan's vertex order as a list of triangles (glTF 2.0, "Meshes"): strip
// triangle i is (v_i, v_i+1+i%2, v_i+2-i%2), fan triangle i is (v_i+1, v_i+2, v_0).
std::vector<uint32_t> triangle_list(const std::vector<uint32_t>& v, bool fan) {
  std::vector<uint32_t> out;
  if (v.size() < 3) return out;
  out.reserve((v.size() - 2) * 3);
  for (size_t i = 0; i + 2 < v.size(); ++i) {
    if (fan) out.insert(out.end(), {v[i + 1], v[i + 2], v[0]});
    else out.insert(out.end(), {v[i], v[i + 1 + i % 2], v[i + 2 - i % 2]});
  }
  return out;
}

// The glTF extensions this loader implements (KHR_mesh_quantization: the integer component
// types of read_floats).
const std::set<std::string> kSupportedExtensions = {
    "KHR_lights_punctual",   "KHR_materials_emissive_strength",     "KHR_materials_ior",
    "KHR_materials_pbrSpecularGlossiness", "KHR_materials_transmission", "KHR_materials_unlit",
    "KHR_mesh_quantization", "KHR_texture_transform"};

std::string supported_extensions() {
  std::string all;
  for (const std::string& e : kSupportedExtensions) all += (all.empty() ? "" : ", ") + e;
  return all;
}

// The names in `names` this loader does not implement, comma-separated ("" when none).
std::string unsupported_extensions(const std::vector<std::string>& names) {
  std::string out;
  for (const std::string& e : names)
    if (!kSupportedExtensions.count(e)) out += (out.empty() ? "" : ", ") + e;
  return out;
}

std::string required_refusal(const std::string& path, const std::string& unsupported) {
  return path + ": requires glTF extensions this loader does not implement: " + unsupported + " (implemented: " +
         supported_extensions() + ")";
}

// The extensionsRequired of a glTF's JSON text, read without tinygltf: for a file tinygltf
// refuses, so that one requiring an extension this loader lacks is refused by that name rather
// than by tinygltf's complaint (KHR_draco_mesh_compression's index accessors have no
// bufferView, which tinygltf calls "accessor[0] invalid bufferView"). Empty when unreadable.
std::vector<std::string> required_extensions(const unsigned char* text, size_t n) {
  std::vector<std::string> out;
  const nlohmann::json j = nlohmann::json::parse(text, text + n, nullptr, /*allow_exceptions=*/false);
  if (!j.is_object()) return out;
  const auto it = j.find("extensionsRequired");
  if (it == j.end() || !it->is_array()) return out;
  for (const auto& e : *it)
    if (e.is_string()) out.push_back(e.get<std::string>());
  return out;
}

// How a material's textures map a primitive's texture coordinates: which TEXCOORD_n set
// (textureInfo.texCoord), and KHR_texture_transform's affine map of it, baked into the
// primitive's coordinates at load. uv' = offset + R(rotation) (scale * uv), R's columns
// (cos, -sin) and (sin, cos): the UVs turn counter-clockwise in glTF's UV space, whose v axis
// points down, as three.js, Babylon.js, Blender and the TextureTransformTest sample model have
// it. The GLSL listing in the extension's text has the transpose, a known error in it
// (KhronosGroup/glTF issue 1563): with it that sample's arrows point at "Error".
struct UvMapping {
  int set = 0;
  bool transformed = false;
  float m[6] = {1, 0, 0, 0, 1, 0};  // u' = m0 u + m1 v + m2, v' = m3 u + m4 v + m5
  bool operator==(const UvMapping& o) const {
    return set == o.set && transformed == o.transformed && std::equal(m, m + 6, o.m);
  }
};

// A textureInfo inside an extension (tinygltf parses only the core ones): index, texCoord and
// its extensions (KHR_texture_transform), or index -1.
tinygltf::TextureInfo texture_info_of(const tinygltf::Value& v) {
  tinygltf::TextureInfo info;
  if (!v.IsObject()) return info;
  const double index = number_or(v, "index", -1), set = number_or(v, "texCoord", 0);
  info.index = index >= 0 && index < 1e9 ? int(index) : -1;
  info.texCoord = set >= 0 && set <= 1024 ? int(set) : -1;
  if (v.Has("extensions") && v.Get("extensions").IsObject()) {
    const tinygltf::Value& e = v.Get("extensions");
    if (e.Has("KHR_texture_transform")) info.extensions["KHR_texture_transform"] = e.Get("KHR_texture_transform");
  }
  return info;
}

// KHR_materials_pbrSpecularGlossiness, as older exporters write materials, or nullptr.
const tinygltf::Value* spec_gloss(const tinygltf::Material& gm) {
  auto it = gm.extensions.find("KHR_materials_pbrSpecularGlossiness");
  return it != gm.extensions.end() && it->second.IsObject() ? &it->second : nullptr;
}

// A material's base colour texture: pbrMetallicRoughness's, or under
// KHR_materials_pbrSpecularGlossiness its diffuse texture (index -1: none).
tinygltf::TextureInfo base_color_texture(const tinygltf::Material& gm) {
  const tinygltf::Value* sg = spec_gloss(gm);
  if (!sg) return gm.pbrMetallicRoughness.baseColorTexture;
  return sg->Has("diffuseTexture") ? texture_info_of(sg->Get("diffuseTexture")) : tinygltf::TextureInfo{};
}

UvMapping uv_mapping(const tinygltf::TextureInfo& info) {
  UvMapping u;
  u.set = info.texCoord;
  auto it = info.extensions.find("KHR_texture_transform");
  if (it == info.extensions.end() || !it->second.IsObject()) return u;
  const tinygltf::Value& t = it->second;
  auto pair = [&](const char* key, float a, float b) -> std::pair<float, float> {
    if (!t.Has(key)) return {a, b};
    const tinygltf::Value& v = t.Get(key);
    if (!v.IsArray() || v.ArrayLen() != 2 || !v.Get(0).IsNumber() || !v.Get(1).IsNumber()) return {a, b};
    return {float(v.Get(0).GetNumberAsDouble()), float(v.Get(1).GetNumberAsDouble())};
  };
  const auto [ou, ov] = pair("offset", 0, 0);
  const auto [su, sv] = pair("scale", 1, 1);
  const float r = float(number_or(t, "rotation", 0));
  if (t.Has("texCoord") && t.Get("texCoord").IsNumber()) {  // a set index; anything else names no set
    const double set = t.Get("texCoord").GetNumberAsDouble();
    u.set = set >= 0 && set <= 1024 ? int(set) : -1;
  }
  if (!(std::isfinite(ou) && std::isfinite(ov) && std::isfinite(su) && std::isfinite(sv) && std::isfinite(r))) return u;
  const float c = std::cos(r), s = std::sin(r);
  u.transformed = true;
  u.m[0] = c * su;  u.m[1] = s * sv; u.m[2] = ou;
  u.m[3] = -s * su; u.m[4] = c * sv; u.m[5] = ov;
  return u;
}

Material convert_material(const tinygltf::Material& gm, const std::map<int, Id>& texture_ids,
                          std::vector<std::string>& warnings, const std::string& file) {
  Material mat;
  mat.model = Material::Model::phong;
  const auto& pbr = gm.pbrMetallicRoughness;
  Vec3 base{float(pbr.baseColorFactor[0]), float(pbr.baseColorFactor[1]), float(pbr.baseColorFactor[2])};
  float alpha = float(pbr.baseColorFactor[3]);
  float metallic = float(pbr.metallicFactor), rough = float(pbr.roughnessFactor);
  auto texture = [&](int index, Id& slot) {
    if (index < 0) return;
    auto it = texture_ids.find(index);
    if (it != texture_ids.end()) slot = it->second;
    else warnings.push_back(file + ": material '" + gm.name + "' references missing texture " + std::to_string(index));
  };
  // KHR_materials_pbrSpecularGlossiness: its diffuse colour and texture take the base colour's
  // place, 1 - glossiness the roughness's, and it is a dielectric.
  if (const tinygltf::Value* sg = spec_gloss(gm)) {
    if (sg->Has("diffuseFactor")) {
      const tinygltf::Value& d = sg->Get("diffuseFactor");
      if (d.IsArray() && d.ArrayLen() == 4) {
        float f[4];
        for (int i = 0; i < 4; ++i) f[i] = d.Get(i).IsNumber() ? float(d.Get(i).GetNumberAsDouble()) : 1.0f;
        base = {f[0], f[1], f[2]};
        alpha = f[3];
      }
    } else {
      base = Vec3{1.0f};
      alpha = 1;
    }
    metallic = 0;
    rough = 1.0f - float(number_or(*sg, "glossinessFactor", 1));
  }
  texture(base_color_texture(gm).index, mat.diffuse_texture);
  // glTF: emission = emissiveFactor (default black) times the emissive texture (sRGB), as the
  // model's emissive colour times its emissive texture.
  texture(gm.emissiveTexture.index, mat.emissive_texture);
  float transmission = 0, ior = 1.5f;
  if (auto it = gm.extensions.find("KHR_materials_transmission"); it != gm.extensions.end())
    transmission = float(number_or(it->second, "transmissionFactor", 0));
  if (auto it = gm.extensions.find("KHR_materials_ior"); it != gm.extensions.end())
    ior = float(number_or(it->second, "ior", 1.5));
  float emissive_strength = 1;
  if (auto it = gm.extensions.find("KHR_materials_emissive_strength"); it != gm.extensions.end())
    emissive_strength = float(number_or(it->second, "emissiveStrength", 1));
  mat.emissive_color = vec3_of(gm.emissiveFactor, {0, 0, 0}) * emissive_strength;

  // Specular lobe: Phong exponent ~ 2/alpha^2 - 2 with alpha = roughness^2 (clamped to XML3D's 0..1 range).
  float a = std::fmax(rough * rough, 1e-3f);
  float exponent = std::fmin(2.0f / (a * a) - 2.0f, 128.0f);
  mat.shininess = std::fmax(exponent, 1.0f) / 128.0f;

  if (transmission > 0) {  // dielectric: refraction with Fresnel reflection
    mat.refraction = transmission;
    mat.ior = ior;
    mat.diffuse_color = base * (1 - transmission);
    mat.specular_color = Vec3{0.04f};
    mat.reflection = 0;  // Fresnel adds reflection to refracting materials
  } else if (metallic >= 0.5f) {  // conductor: mirror reflection tinted by the base colour
    float gloss = 1.0f - std::fmin(rough * 2.0f, 0.9f);
    mat.reflection = std::fmin(max_component(base), 1.0f) * gloss;
    mat.diffuse_color = base * (1.0f - gloss);
    mat.specular_color = base;
  } else {
    mat.diffuse_color = base;
    mat.specular_color = Vec3{rough < 0.5f ? 0.04f * (1 - rough) * 4 : 0.0f};
  }
  if (gm.alphaMode == "MASK") {
    mat.alpha_mask = true;
    mat.alpha_cutoff = float(gm.alphaCutoff);
    mat.opacity = alpha;
  } else if (gm.alphaMode == "BLEND") {
    mat.opacity = alpha;  // see-through weighted by 1 - opacity
  }
  if (gm.extensions.count("KHR_materials_unlit")) {  // the base colour as it is, no lighting
    mat.model = Material::Model::matte;
    mat.diffuse_color = base;
    mat.reflection = mat.refraction = 0;
    mat.specular_color = Vec3{0.0f};
  }
  mat.double_sided = gm.doubleSided;
  mat.use_vertex_color = true;  // glTF: a primitive's COLOR_0 multiplies the base colour (meshes without one: no change)
  return mat;
}

// External files (buffers, images) are read only from the glTF file's folder and below: a
// path that climbs out with "..", after tinygltf has decoded the URI and joined it with the
// folder (or with ".", its fallback), is refused with an error naming the path. tinygltf
// joins absolute URIs to the folder too ("folder//etc/passwd"), so they stay inside it; with
// no folder in the path (a file in the working directory) an absolute one is refused here.
// data: URIs never reach the file system.
struct FolderJail {
  std::filesystem::path folder;  // absolute, lexically normal
};

bool inside(const std::filesystem::path& folder, const std::filesystem::path& p) {
  auto f = folder.begin(), q = p.begin();
  for (; f != folder.end(); ++f, ++q) {
    if (f->empty()) continue;  // a trailing separator's empty element
    if (q == p.end() || *f != *q) return false;
  }
  return true;
}

bool jailed_read(std::vector<unsigned char>* out, std::string* err, const std::string& filepath, void* user) {
  const auto& jail = *static_cast<const FolderJail*>(user);
  std::error_code ec;
  const std::filesystem::path abs = std::filesystem::absolute(filepath, ec).lexically_normal();
  if (ec || !inside(jail.folder, abs)) {
    if (err)
      *err += "refused: '" + filepath + "' lies outside the glTF file's folder " + jail.folder.string() +
              " (external URIs must be relative paths inside it)";
    return false;
  }
  return tinygltf::ReadWholeFile(out, err, filepath, nullptr);
}

// Images are decoded after tinygltf has read the file, all at once in parallel (TBB): tinygltf
// would decode them one after another while it parses. Its image callback only keeps the
// encoded bytes of each image.
struct EncodedImages {
  std::vector<std::vector<uint8_t>> bytes;  // by image index
};

bool keep_encoded(tinygltf::Image* image, const int index, std::string*, std::string*, int, int,
                  const unsigned char* bytes, int size, void* user) {
  auto& images = *static_cast<EncodedImages*>(user);
  if (index < 0) return false;
  if (size_t(index) >= images.bytes.size()) images.bytes.resize(size_t(index) + 1);
  images.bytes[size_t(index)].assign(bytes, bytes + std::max(size, 0));
  image->width = image->height = -1;  // decoded later
  return true;
}

// tinygltf turns JSON under "extras" and "extensions" into its Values recursively, one stack
// frame a level: 100000 nested brackets (200 KB) overflowed the stack. Files nested deeper
// than this are refused before tinygltf parses them (glTF's own structure nests fewer than ten).
constexpr size_t kMaxJsonDepth = 256;

// The deepest nesting of arrays and objects in JSON text (brackets inside strings skipped).
size_t json_depth(const unsigned char* p, size_t n) {
  size_t depth = 0, deepest = 0;
  bool in_string = false;
  for (size_t i = 0; i < n; ++i) {
    const unsigned char c = p[i];
    if (in_string) {
      if (c == '\\') ++i;
      else if (c == '"') in_string = false;
    } else if (c == '"') {
      in_string = true;
    } else if (c == '[' || c == '{') {
      deepest = std::max(deepest, ++depth);
    } else if ((c == ']' || c == '}') && depth > 0) {
      --depth;
    }
  }
  return deepest;
}

// The JSON text of a glTF file: all of a .gltf, the first chunk of a .glb (as far as it lies in
// the file; tinygltf checks the rest of the container).
std::pair<const unsigned char*, size_t> json_text(const std::vector<unsigned char>& file, bool binary) {
  if (!binary) return {file.data(), file.size()};
  if (file.size() < 20) return {file.data(), 0};
  uint32_t length = 0;
  std::memcpy(&length, file.data() + 12, 4);  // little-endian, as the .glb header
  return {file.data() + 20, std::min<size_t>(length, file.size() - 20)};
}

double ms_since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
}

}  // namespace

LoadedScene load_gltf(const std::string& path, const GltfOptions& options) {
  const auto t0 = std::chrono::steady_clock::now();
  tinygltf::TinyGLTF ctx;
  EncodedImages encoded;
  ctx.SetImageLoader(&keep_encoded, &encoded);
  tinygltf::Model model;
  std::string err, warn;
  bool ok = false;
  FolderJail jail;
  {
    std::error_code ec;
    jail.folder = std::filesystem::absolute(path, ec).lexically_normal().parent_path();
  }
  tinygltf::FsCallbacks fs{&tinygltf::FileExists, &tinygltf::ExpandFilePath, &jailed_read, &tinygltf::WriteWholeFile, &jail};
  ctx.SetFsCallbacks(fs);
  try {
    // Read here (through the jail, as tinygltf's *FromFile would) so that the JSON's nesting is
    // checked before tinygltf parses it.
    const bool binary = path.size() > 4 && path.compare(path.size() - 4, 4, ".glb") == 0;
    std::vector<unsigned char> file;
    std::string read_err;
    if (!jailed_read(&file, &read_err, path, &jail)) throw LoadError(path + ": cannot read file: " + read_err);
    if (file.size() > std::numeric_limits<unsigned int>::max()) throw LoadError(path + ": file larger than 4 GiB");
    const auto [text, text_size] = json_text(file, binary);
    if (json_depth(text, text_size) > kMaxJsonDepth)
      throw LoadError(path + ": JSON nested deeper than " + std::to_string(kMaxJsonDepth) + " levels");
    const std::string base_dir = tinygltf::GetBaseDir(path);
    if (binary)
      ok = ctx.LoadBinaryFromMemory(&model, &err, &warn, file.data(), static_cast<unsigned int>(file.size()), base_dir);
    else if (file.empty())
      err = "empty file";
    else
      ok = ctx.LoadASCIIFromString(&model, &err, &warn, reinterpret_cast<const char*>(file.data()),
                                   static_cast<unsigned int>(file.size()), base_dir);
    // tinygltf may refuse a file that requires an extension this loader lacks before the check
    // below sees it (Draco's accessors without bufferViews): such a file is refused by name.
    if (!ok)
      if (const std::string required = unsupported_extensions(required_extensions(text, text_size)); !required.empty())
        throw LoadError(required_refusal(path, required));
  } catch (const LoadError&) {
    throw;
  } catch (const std::exception& e) {
    throw LoadError(path + ": " + e.what());
  }
  if (!ok) throw LoadError(path + ": " + (err.empty() ? "cannot load glTF" : err));

  LoadedScene out;
  // Extensions: a file that requires one this loader does not implement is refused by name
  // (Draco or meshopt compressed geometry would otherwise load as nothing, or as garbage),
  // before its bufferViews are checked (meshopt's lie in a fallback buffer without data);
  // ones it only uses are named in one warning, and the file loads without them.
  {
    if (const std::string required = unsupported_extensions(model.extensionsRequired); !required.empty())
      throw LoadError(required_refusal(path, required));
    if (const std::string used = unsupported_extensions(model.extensionsUsed); !used.empty())
      out.warnings.push_back(path + ": glTF extensions ignored: " + used);
  }
  check_buffer_views(model, path);
  out.times.parse_ms = ms_since(t0);
  Scene& scene = out.scene;

  // Every image a texture uses, decoded to RGBA8 (in parallel unless options say otherwise).
  const auto t_images = std::chrono::steady_clock::now();
  std::vector<int> used(model.images.size(), 0);  // textures that use each image
  for (const auto& gt : model.textures)
    if (gt.source >= 0 && size_t(gt.source) < used.size()) used[size_t(gt.source)]++;
  std::vector<Image> decoded(model.images.size());
  std::vector<std::string> decode_errors(model.images.size());
  auto decode = [&](size_t i) {
    if (!used[i] || i >= encoded.bytes.size() || encoded.bytes[i].empty()) return;
    if (!decode_image(encoded.bytes[i].data(), encoded.bytes[i].size(), decoded[i], decode_errors[i])) decoded[i] = Image{};
    std::vector<uint8_t>().swap(encoded.bytes[i]);
  };
  if (options.parallel_images)
    tbb::parallel_for(size_t(0), model.images.size(), decode);
  else
    for (size_t i = 0; i < model.images.size(); ++i) decode(i);
  out.times.images_ms = ms_since(t_images);
  const auto t_convert = std::chrono::steady_clock::now();
  if (!warn.empty()) out.warnings.push_back(path + ": " + warn);
  Id next_id = 1;

  // Textures: decode images (tinygltf already did, via stb_image) and attach the sampler.
  std::map<int, Id> texture_ids;
  std::vector<SharedBytes> shared(model.images.size());  // each image's bytes, once a texture took them
  bool mirrored_said = false;  // one warning for the file's mirrored samplers
  for (size_t ti = 0; ti < model.textures.size(); ++ti) {
    const auto& gt = model.textures[ti];
    if (gt.source < 0 || size_t(gt.source) >= model.images.size()) {
      out.warnings.push_back(path + ": texture " + std::to_string(ti) + " has no image");
      continue;
    }
    Image& img = decoded[size_t(gt.source)];
    SharedBytes& bytes = shared[size_t(gt.source)];
    if (bytes.empty() && (img.width <= 0 || img.height <= 0 || img.rgba.size() != size_t(img.width) * size_t(img.height) * 4)) {
      const std::string& why = decode_errors[size_t(gt.source)];
      out.warnings.push_back(path + ": image '" + model.images[gt.source].uri + "' could not be decoded" +
                             (why.empty() ? "" : " (" + why + ")") + "; texture left out");
      continue;
    }
    Texture tex;
    tex.width = img.width;
    tex.height = img.height;
    // Textures of one image share its bytes.
    if (bytes.empty()) bytes = SharedBytes(std::move(img.rgba));
    tex.rgba = bytes;
    if (gt.sampler >= 0 && size_t(gt.sampler) < model.samplers.size()) {
      const auto& s = model.samplers[gt.sampler];
      auto wrap = [](int w) { return w == TINYGLTF_TEXTURE_WRAP_CLAMP_TO_EDGE ? Sampler::Wrap::clamp : Sampler::Wrap::repeat; };
      tex.sampler.wrap_s = wrap(s.wrapS);
      tex.sampler.wrap_t = wrap(s.wrapT);
      tex.sampler.filter = s.magFilter == TINYGLTF_TEXTURE_FILTER_NEAREST ? Sampler::Filter::nearest : Sampler::Filter::linear;
      if ((s.wrapS == TINYGLTF_TEXTURE_WRAP_MIRRORED_REPEAT || s.wrapT == TINYGLTF_TEXTURE_WRAP_MIRRORED_REPEAT) && !mirrored_said) {
        out.warnings.push_back(path + ": sampler " + std::to_string(gt.sampler) +
                               " wraps by MIRRORED_REPEAT, which is drawn as REPEAT");
        mirrored_said = true;
      }
    }
    Id id = next_id++;
    scene.set_texture(id, std::move(tex));
    texture_ids[int(ti)] = id;
  }

  std::vector<Id> material_ids(model.materials.size(), kNoId);
  std::vector<UvMapping> uv_of(model.materials.size());  // the texture coordinates each material's textures read
  for (size_t mi = 0; mi < model.materials.size(); ++mi) {
    material_ids[mi] = next_id++;
    const auto& gm = model.materials[mi];
    scene.set_material(material_ids[mi], convert_material(gm, texture_ids, out.warnings, path));
    // A mesh has one set of texture coordinates: the base colour texture's, else the emissive's.
    const tinygltf::TextureInfo base = base_color_texture(gm);
    const auto& emissive = gm.emissiveTexture;
    uv_of[mi] = uv_mapping(base.index >= 0 ? base : emissive);
    if (base.index >= 0 && emissive.index >= 0 && !(uv_mapping(emissive) == uv_of[mi]))
      out.warnings.push_back(path + ": material '" + gm.name +
                             "': its emissive texture reads other texture coordinates than its base colour texture; "
                             "both read the base colour's");
  }

  // Geometry: one set of buffers per primitive, shared by every node that instances the mesh.
  struct Prim {
    Id positions = kNoId, normals = kNoId, texcoords = kNoId, colors = kNoId, indices = kNoId, material = kNoId;
    std::vector<float> pos;  // kept for bounds
    float max_abs = 0;       // largest |coordinate| (for the world-box check)
  };
  std::vector<std::vector<Prim>> prims(model.meshes.size());
  for (size_t mi = 0; mi < model.meshes.size(); ++mi) {
    const auto& gmesh = model.meshes[mi];
    for (size_t pi = 0; pi < gmesh.primitives.size(); ++pi) {
      const auto& p = gmesh.primitives[pi];
      std::string what = path + ": mesh '" + gmesh.name + "' primitive " + std::to_string(pi);
      const bool strip = p.mode == TINYGLTF_MODE_TRIANGLE_STRIP, fan = p.mode == TINYGLTF_MODE_TRIANGLE_FAN;
      if (p.mode != TINYGLTF_MODE_TRIANGLES && p.mode != -1 && !strip && !fan) {
        out.warnings.push_back(what + ": mode " + std::to_string(p.mode) + " (points or lines) is not triangles; left out");
        continue;
      }
      auto pit = p.attributes.find("POSITION");
      if (pit == p.attributes.end()) throw LoadError(what + ": no POSITION attribute");
      Prim prim;
      prim.pos = read_floats(model, pit->second, 3, what + " POSITION");
      size_t nv = prim.pos.size() / 3;
      for (float v : prim.pos) {
        if (!std::isfinite(v)) throw LoadError(what + ": POSITION holds NaN or Inf");
        prim.max_abs = std::fmax(prim.max_abs, std::fabs(v));
      }
      auto add_floats = [&](std::vector<float> values, uint8_t components) {
        Buffer b;
        b.components = components;
        b.f = std::move(values);
        Id id = next_id++;
        scene.set_buffer(id, std::move(b));
        return id;
      };
      prim.positions = add_floats(prim.pos, 3);
      if (auto it = p.attributes.find("NORMAL"); it != p.attributes.end())
        prim.normals = add_floats(read_floats(model, it->second, 3, what + " NORMAL"), 3);
      {
        const UvMapping uv = p.material >= 0 && size_t(p.material) < uv_of.size() ? uv_of[size_t(p.material)] : UvMapping{};
        const std::string set = "TEXCOORD_" + std::to_string(uv.set);
        if (auto it = p.attributes.find(set); it != p.attributes.end()) {
          std::vector<float> t = read_floats(model, it->second, 2, what + " " + set);
          if (uv.transformed)
            for (size_t i = 0; i + 1 < t.size(); i += 2) {
              const float u = t[i], v = t[i + 1];
              t[i] = uv.m[0] * u + uv.m[1] * v + uv.m[2];
              t[i + 1] = uv.m[3] * u + uv.m[4] * v + uv.m[5];
            }
          prim.texcoords = add_floats(std::move(t), 2);
        }
      }
      // COLOR_0: RGB or RGBA (alpha left out), float or normalised unsigned byte/short; linear.
      if (auto it = p.attributes.find("COLOR_0"); it != p.attributes.end()) {
        const int index = it->second;
        const int nc = index >= 0 && size_t(index) < model.accessors.size()
                           ? tinygltf::GetNumComponentsInType(model.accessors[size_t(index)].type)
                           : 0;
        if (nc != 3 && nc != 4) throw LoadError(what + " COLOR_0: expected 3 or 4 components");
        std::vector<float> c = read_floats(model, index, nc, what + " COLOR_0");
        std::vector<float> rgb;
        rgb.reserve(c.size() / size_t(nc) * 3);
        for (size_t i = 0; i + size_t(nc) <= c.size(); i += size_t(nc)) rgb.insert(rgb.end(), {c[i], c[i + 1], c[i + 2]});
        bool finite = true;
        for (float v : rgb) finite = finite && std::isfinite(v);
        if (rgb.size() / 3 != nv)
          out.warnings.push_back(what + ": COLOR_0 has " + std::to_string(rgb.size() / 3) + " elements, POSITION " +
                                 std::to_string(nv) + "; colours left out");
        else if (!finite)
          out.warnings.push_back(what + ": COLOR_0 holds NaN or Inf; colours left out");
        else
          prim.colors = add_floats(std::move(rgb), 3);
      }
      if (p.indices >= 0 || strip || fan) {
        Buffer ib;
        ib.type = Buffer::Type::u32;
        if (p.indices >= 0) {
          ib.u = read_indices(model, p.indices, what);
        } else {
          ib.u.resize(nv);
          for (size_t i = 0; i < nv; ++i) ib.u[i] = uint32_t(i);
        }
        for (uint32_t i : ib.u)
          if (i >= nv) throw LoadError(what + ": index " + std::to_string(i) + " >= vertex count " + std::to_string(nv));
        if (strip || fan) ib.u = triangle_list(ib.u, fan);
        if (ib.u.size() % 3) throw LoadError(what + ": index count is not a multiple of 3");
        prim.indices = next_id++;
        scene.set_buffer(prim.indices, std::move(ib));
      } else if (nv % 3) {
        throw LoadError(what + ": non-indexed vertex count is not a multiple of 3");
      }
      if (p.material >= 0 && size_t(p.material) < material_ids.size()) prim.material = material_ids[p.material];
      prims[mi].push_back(std::move(prim));
    }
  }

  // Nodes: walk the default scene, instancing meshes, picking up the first camera and the lights.
  int scene_index = model.defaultScene >= 0 ? model.defaultScene : 0;
  std::vector<int> roots;
  if (size_t(scene_index) < model.scenes.size()) {
    roots = model.scenes[scene_index].nodes;
  } else if (model.scenes.empty()) {
    // A file without scenes (glTF allows it): every node tree is drawn, its roots the nodes that
    // are no node's child, as the web reader does.
    std::vector<uint8_t> is_child(model.nodes.size(), 0);
    for (const auto& n : model.nodes)
      for (int c : n.children)
        if (c >= 0 && size_t(c) < is_child.size()) is_child[size_t(c)] = 1;
    for (size_t i = 0; i < model.nodes.size(); ++i)
      if (!is_child[i]) roots.push_back(int(i));
  }
  const tinygltf::Value* lights_ext = nullptr;
  if (auto it = model.extensions.find("KHR_lights_punctual"); it != model.extensions.end()) lights_ext = &it->second;

  // glTF's nodes form disjoint trees: a node has at most one parent and is reached once. A node
  // reached a second time (a second parent, a cycle, a root listed twice) is refused: otherwise
  // each node listing the next one twice doubles the walk (64 such nodes, 1.4 KB, would never
  // finish), and a cycle would recurse until the depth check.
  std::vector<uint8_t> reached(model.nodes.size(), 0);
  std::string other_camera;  // the warning for a camera of another type, said if it stays
  std::function<void(int, const Mat4&, int)> visit = [&](int ni, const Mat4& parent, int depth) {
    if (ni < 0 || size_t(ni) >= model.nodes.size()) throw LoadError(path + ": node index " + std::to_string(ni) + " out of range");
    if (reached[size_t(ni)])
      throw LoadError(path + ": node " + std::to_string(ni) +
                      " is reached twice from the scene (a second parent, a cycle or a repeated root; glTF nodes form trees)");
    reached[size_t(ni)] = 1;
    if (depth > 256) throw LoadError(path + ": node hierarchy deeper than 256");
    const auto& node = model.nodes[ni];
    Mat4 world = parent * node_local(node);
    if (!world.finite()) throw LoadError(path + ": node '" + node.name + "' has a non-finite transform");
    const std::string node_name = path + ": node " + std::to_string(ni) + " '" + node.name + "'";
    // A zero or nearly zero scale is a common way to hide a node: its meshes are left out
    // with a warning and the rest of the scene loads (core/validate.h has the bounds).
    const TransformFigures figures = transform_figures(world);  // finite: checked above
    const std::string mesh_why = check_transform(figures, kMeshLimits);
    if (node.mesh >= 0 && size_t(node.mesh) < prims.size() && !mesh_why.empty())
      out.warnings.push_back(node_name + ": world transform: " + mesh_why + "; its meshes are left out");
    if (node.mesh >= 0 && size_t(node.mesh) < prims.size() && mesh_why.empty()) {
      for (const Prim& prim : prims[node.mesh]) {
        if (std::string why = check_world_extent(figures, prim.max_abs); !why.empty()) {
          out.warnings.push_back(node_name + ": world transform: " + why + "; mesh left out");
          continue;
        }
        Mesh mesh;
        mesh.positions = prim.positions;
        mesh.normals = prim.normals;
        mesh.texcoords = prim.texcoords;
        mesh.colors = prim.colors;
        mesh.indices = prim.indices;
        mesh.material = prim.material;
        mesh.transform = world;
        scene.set_mesh(next_id++, mesh);
        for (size_t i = 0; i + 2 < prim.pos.size(); i += 3)
          out.bounds.extend(world.transform_point({prim.pos[i], prim.pos[i + 1], prim.pos[i + 2]}));
      }
    }
    // The first perspective camera, as the web reader takes it; else the first other one,
    // drawn as a perspective one (the renderers have pinhole cameras only).
    const bool perspective_set = out.has_camera && other_camera.empty();
    if (node.camera >= 0 && size_t(node.camera) < model.cameras.size() && !perspective_set) {
      const auto& cam = model.cameras[node.camera];
      const bool perspective = cam.type == "perspective";
      if (perspective || !out.has_camera) {
        Camera c;
        c.to_world = world;
        if (perspective) c.fov_y = float(cam.perspective.yfov);
        if (std::string why = check_camera(c); !why.empty()) {
          out.warnings.push_back(node_name + ": camera ignored: " + why);
        } else {
          scene.set_camera(c);
          out.has_camera = true;
          other_camera = perspective ? std::string() : node_name + ": camera of type '" + cam.type +
                                                           "' drawn as a perspective one with a " +
                                                           std::to_string(int(std::lround(c.fov_y * 180 / kPi))) +
                                                           " degree field of view";
        }
      }
    }
    if (auto it = node.extensions.find("KHR_lights_punctual"); it != node.extensions.end() && lights_ext) {
      // Converted only within int's range: a double beyond it (1e300) makes the cast undefined.
      const double index = number_or(it->second, "light", -1);
      const int li = index >= 0 && index < 1e9 ? int(index) : -1;
      const auto& arr = lights_ext->Get("lights");
      if (li >= 0 && arr.IsArray() && size_t(li) < arr.ArrayLen()) {
        const auto& gl = arr.Get(li);
        Light l;
        std::string type = gl.Get("type").IsString() ? gl.Get("type").Get<std::string>() : "point";
        l.type = type == "directional" ? Light::Type::directional : type == "spot" ? Light::Type::spot : Light::Type::point;
        if (gl.Has("color") && gl.Get("color").IsArray() && gl.Get("color").ArrayLen() == 3)
          l.color = {float(gl.Get("color").Get(0).GetNumberAsDouble()), float(gl.Get("color").Get(1).GetNumberAsDouble()),
                     float(gl.Get("color").Get(2).GetNumberAsDouble())};
        l.intensity = float(number_or(gl, "intensity", 1.0));
        l.position = world.transform_point({0, 0, 0});
        l.direction = normalize(world.transform_vector({0, 0, -1}));
        l.attenuation = {0, 0, 1};  // glTF: inverse square
        if (l.type == Light::Type::spot && gl.Has("spot")) {
          float inner = float(number_or(gl.Get("spot"), "innerConeAngle", 0));
          float outer = float(number_or(gl.Get("spot"), "outerConeAngle", kPi / 4));
          l.cutoff = outer;
          l.softness = outer > 0 ? 1.0f - inner / outer : 0.0f;
        }
        std::string why;
        if (l.type != Light::Type::directional && !(why = check_point(l.position)).empty()) why = "position " + why;
        if (why.empty() && l.type != Light::Type::point && !(why = check_direction(l.direction)).empty())
          why = "direction " + why;
        if (why.empty()) scene.set_light(next_id++, l);
        else out.warnings.push_back(node_name + ": light ignored: " + why);
      }
    }
    for (int child : node.children) visit(child, world, depth + 1);
  };
  for (int r : roots) visit(r, Mat4{}, 0);
  if (!other_camera.empty()) out.warnings.push_back(other_camera);

  // The sky: an ambient term of the sky's average radiance over the upper hemisphere.
  Environment env;
  env.linear = true;
  if (size_t(scene_index) < model.scenes.size()) {
    const auto& extras = model.scenes[scene_index].extras;
    if (extras.IsObject() && extras.Has("environment")) {
      const auto& e = extras.Get("environment");
      double integral = -1;
      if (e.Has("analysis")) integral = number_or(e.Get("analysis"), "integral_L_dOmega", -1);
      if (integral < 0 && lights_ext && lights_ext->Has("lights")) {
        const auto& arr = lights_ext->Get("lights");
        for (size_t i = 0; i < arr.ArrayLen(); ++i)
          if (arr.Get(int(i)).Has("extras")) integral = std::fmax(integral, number_or(arr.Get(int(i)).Get("extras"), "sky_total_L_dOmega", -1));
      }
      if (integral > 0) {
        float l = float(integral / (2.0 * kPi));
        env.ambient = Vec3{l};
        env.background = Vec3{l * 0.8f, l * 0.9f, l * 1.1f};
        // Expose so that a white surface under the sky alone is mid grey.
        env.exposure = l > 0.3f ? 0.3f / l : 1.0f;
      }
    }
  }
  scene.set_environment(env);
  // What a glTF viewer would play that this loader does not: said once, so that a model drawn
  // in its rest pose is not taken for a broken file.
  {
    size_t morphed = 0;
    for (const auto& m : model.meshes)
      for (const auto& p : m.primitives) morphed += p.targets.empty() ? 0 : 1;
    std::string still;
    auto add = [&](size_t n, const char* what) {
      if (n) still += (still.empty() ? "" : ", ") + std::to_string(n) + " " + what;
    };
    add(model.animations.size(), model.animations.size() == 1 ? "animation" : "animations");
    add(model.skins.size(), model.skins.size() == 1 ? "skin" : "skins");
    add(morphed, morphed == 1 ? "primitive with morph targets" : "primitives with morph targets");
    if (!still.empty())
      out.warnings.push_back(path + ": " + still + " not played: the meshes are drawn in the file's rest pose");
  }
  if (!out.has_camera) {
    Camera c;
    if (out.bounds.valid()) {
      Vec3 center = (out.bounds.lo + out.bounds.hi) * 0.5f;
      Camera fit = c;
      fit.to_world = Mat4::look_at(center + Vec3{0, 0, out.bounds.extent()}, center, {0, 1, 0});
      if (check_camera(fit).empty()) c = fit;  // else (bounds at the world's edge) the identity camera
    }
    scene.set_camera(c);
  }
  // A file with lit materials and no lights and no sky (many exported models: glTF viewers light
  // them with a default environment) renders them black, as an XML3D page without lights does,
  // and the caller is told (`dark`). With options.default_lighting it gets a sun over the
  // camera's left shoulder and a sky of about the pavilion's (an ambient term) instead; the
  // background stays as the file has it. All-unlit files (XML3D's matte) are neither.
  bool lit = false;
  for (const auto& [id, m] : scene.materials()) lit = lit || m.value.model != Material::Model::matte;
  out.dark = lit && scene.lights().empty() && !(env.ambient.x > 0 || env.ambient.y > 0 || env.ambient.z > 0);
  if (out.dark && options.default_lighting) {
    out.dark = false;
    Light sun;
    sun.type = Light::Type::directional;
    const Vec3 d = normalize(scene.camera().to_world.transform_vector({0.4f, -0.7f, -0.6f}));
    sun.direction = check_direction(d).empty() ? d : normalize(Vec3{0.4f, -0.7f, -0.6f});
    scene.set_light(next_id++, sun);
    env.ambient = Vec3{0.3f};
    scene.set_environment(env);
    out.default_lighting = true;
  }
  out.times.convert_ms = ms_since(t_convert);
  return out;
}

std::string lighting_note(const std::string& path, const LoadedScene& loaded) {
  if (loaded.default_lighting)
    return path + ": no lights (KHR_lights_punctual) and no sky: lit by a default sun over the camera's shoulder and "
                  "a sky (--default-light)";
  if (loaded.dark)
    return path + ": no lights (KHR_lights_punctual) and no sky: its lit materials render black, as in an XML3D "
                  "page without lights; --default-light adds a sun and a sky";
  return "";
}

Camera CameraLoop::camera(size_t frame) const {
  Camera c;
  c.fov_y = fov_y_deg * kPi / 180.0f;
  if (frames.empty()) return c;
  const Frame& f = frames[frame % frames.size()];
  c.to_world = Mat4::look_at(f.eye, f.target, f.up);
  return c;
}

CameraLoop load_camera_loop(const std::string& path) {
  std::ifstream in(path);
  if (!in) throw LoadError(path + ": cannot open camera loop");
  CameraLoop loop;
  double fov = 0;
  // Numbers are read as double and checked before they become floats (1e39 would overflow).
  std::vector<std::array<double, 9>> raw;
  try {
    auto j = nlohmann::json::parse(in);
    fov = j.at("fovY_deg").get<double>();
    for (const auto& f : j.at("frames")) {
      std::array<double, 9> v{};
      int k = 0;
      for (const char* key : {"eye", "target", "up"})
        for (int c = 0; c < 3; ++c) v[size_t(k++)] = f.at(key).at(size_t(c)).get<double>();
      raw.push_back(v);
    }
  } catch (const std::exception& e) {
    throw LoadError(path + ": " + e.what());
  }
  if (raw.empty()) throw LoadError(path + ": camera loop has no frames");
  // The field of view: the kernel clamps to (1e-6 rad, 180 deg - 1e-4 rad); a loop asks for a sane one.
  if (!(fov >= 1e-3 && fov <= 179)) throw LoadError(path + ": fovY_deg must be in [0.001, 179]");
  loop.fov_y_deg = float(fov);
  for (size_t i = 0; i < raw.size(); ++i) {
    const auto& v = raw[i];
    const std::string where = path + ": frame " + std::to_string(i) + ": ";
    for (size_t k = 0; k < 9; ++k)
      if (!(std::fabs(v[k]) <= kWorldLimit))  // also NaN
      {
        char num[32];
        std::snprintf(num, sizeof num, "%g", v[k]);
        throw LoadError(where + (k < 3 ? "eye" : k < 6 ? "target" : "up") + " component " + num +
                        " is not finite or beyond the world limit 2^32");
      }
    CameraLoop::Frame f{{float(v[0]), float(v[1]), float(v[2])}, {float(v[3]), float(v[4]), float(v[5])},
                        {float(v[6]), float(v[7]), float(v[8])}};
    const Vec3 view = f.target - f.eye;
    if (!(length(view) > 0)) throw LoadError(where + "eye and target are the same point");
    if (!check_direction(view).empty()) throw LoadError(where + "the view direction (target - eye) " + check_direction(view));
    if (!check_direction(f.up).empty()) throw LoadError(where + "up " + check_direction(f.up));
    if (length(cross(normalize(view), normalize(f.up))) < 1e-3f)
      throw LoadError(where + "up is parallel to the view direction");
    Camera c;
    c.fov_y = loop.fov_y_deg * kPi / 180.0f;
    c.to_world = Mat4::look_at(f.eye, f.target, f.up);
    if (std::string why = check_camera(c); !why.empty()) throw LoadError(where + "camera " + why);
    loop.frames.push_back(f);
  }
  return loop;
}

}  // namespace tessera
