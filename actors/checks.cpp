// What a node checks of what its peers send (checks.h).
#include "actors/checks.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <stdexcept>

#include "lb/sat.h"
#include "renderer/renderer.h"
#include "update/scene_update.h"

namespace tessera {

RenderTask task_of(const RenderBatch& b, const Rect& pixels) {
  RenderTask t;
  t.frame = b.frame;
  t.width = b.width;
  t.height = b.height;
  t.pixels = pixels;
  t.ao_samples = b.ao_samples;
  t.max_depth = b.max_depth;
  t.renderer = b.renderer;
  t.sample = b.sample;
  t.seed = b.seed;
  t.radiance = b.radiance;
  t.hit_points = b.hit_points;
  t.guides = b.guides;
  // (A batch refused by check_batch still gets its tasks' failed tiles: no plan then. check_plan
  // first: it compares a peer's rectangles before anything subtracts their coordinates.)
  if (!b.plan.empty() && check_plan(b.plan_blocks, b.plan, b.width, b.height, pixels).empty() && !pixels.empty()) {
    t.plan_blocks = intersect(b.plan_blocks, plan_blocks_of(pixels));
    t.plan = crop_plan(b.plan_blocks, b.plan, t.plan_blocks);
  }
  return t;
}

std::string check_plan(const Rect& blocks, const std::vector<uint32_t>& plan, int32_t width, int32_t height,
                       const Rect& pixels) {
  if (plan.empty()) return {};
  // Compared, never subtracted, until they are known to lie inside the frame: they may come
  // from a peer (Rect::width of [-2^31, 2^31) overflows).
  constexpr int32_t kMaxSide = 1 << 24;
  if (width < 1 || height < 1 || width > kMaxSide || height > kMaxSide) return "a plan for a frame of impossible size";
  const auto inside = [](const Rect& r, int32_t w, int32_t h) {
    return r.x0 >= 0 && r.y0 >= 0 && r.x0 <= r.x1 && r.y0 <= r.y1 && r.x1 <= w && r.y1 <= h;
  };
  const Rect all = plan_blocks_of({0, 0, width, height});
  if (!inside(blocks, all.x1, all.y1) || blocks.x0 == blocks.x1 || blocks.y0 == blocks.y1)
    return "a plan of blocks outside the frame's blocks";
  if (!inside(pixels, width, height)) return "a plan for a task outside the frame";
  if (plan.size() != uint64_t(blocks.area()))
    return "a plan of " + std::to_string(plan.size()) + " entries for " + std::to_string(blocks.area()) + " blocks";
  if (!blocks.contains(plan_blocks_of(pixels))) return "a plan of blocks that does not cover its task";
  return {};
}

std::vector<uint32_t> crop_plan(const Rect& blocks, const std::vector<uint32_t>& plan, const Rect& to) {
  if (to.empty()) return {};
  if (!blocks.contains(to) || plan.size() != uint64_t(blocks.area()))
    throw std::invalid_argument("crop_plan: a part outside the plan");
  std::vector<uint32_t> out;
  out.reserve(size_t(to.area()));
  for (int32_t y = to.y0; y < to.y1; ++y) {
    const auto row = plan.begin() + long(size_t(y - blocks.y0) * size_t(blocks.width()) + size_t(to.x0 - blocks.x0));
    out.insert(out.end(), row, row + to.width());
  }
  return out;
}

std::string check_tile(const TileResult& t, uint32_t frame, const Rect& expected, PacketLayout layout, int32_t width,
                       int32_t height, bool radiance, uint8_t guides) {
  auto str = [](const Rect& r) {
    return "[" + std::to_string(r.x0) + "," + std::to_string(r.y0) + "," + std::to_string(r.x1) + "," +
           std::to_string(r.y1) + "]";
  };
  if (t.frame != frame) return "tile of frame " + std::to_string(t.frame) + " in frame " + std::to_string(frame);
  if (!(t.pixels == expected)) return "tile " + str(t.pixels) + " for task " + str(expected);
  if (!std::isfinite(t.kernel_ms) || t.kernel_ms < 0 || !std::isfinite(t.rendering_ms) || t.rendering_ms < 0 ||
      !std::isfinite(t.sat_ms) || t.sat_ms < 0)
    return "impossible timings";
  if (t.cancelled) {  // stopped early (TileResult::cancelled): its figures, and nothing else
    if (!t.rgba.empty() || !t.radiance.empty() || !t.guides.empty() || !t.sat.empty() || !t.depth.empty())
      return "tile " + str(expected) + " that stopped early and still carries pixels";
    return {};
  }
  if (t.rgba.size() != size_t(expected.area()) * 4)
    return "tile " + str(expected) + " with " + std::to_string(t.rgba.size()) + " bytes of pixels, expected " +
           std::to_string(size_t(expected.area()) * 4);
  const size_t want_radiance = radiance ? size_t(expected.area()) * 12 : 0;
  if (t.radiance.size() != want_radiance)
    return "tile " + str(expected) + " with " + std::to_string(t.radiance.size()) + " bytes of radiance, expected " +
           std::to_string(want_radiance);
  for (size_t i = 0; i + 4 <= t.radiance.size(); i += 4) {  // finite and not negative, as a renderer writes it
    float v;
    std::memcpy(&v, t.radiance.data() + i, 4);
    if (!(v >= 0 && v <= 3.0e38f)) return "tile " + str(expected) + " with radiance that is negative or not finite";
  }
  const size_t guide_floats = guides == kAllGuides ? size_t(kGuideFloats) : guides == kOpenGuides ? 1 : 0;
  const size_t want_guides = size_t(expected.area()) * guide_floats * 4;
  if (t.guides.size() != want_guides)
    return "tile " + str(expected) + " with " + std::to_string(t.guides.size()) + " bytes of guides, expected " +
           std::to_string(want_guides);
  // As a renderer writes them: finite; distances >= 0 or -1 (a miss), ambient light >= 0, open
  // fractions in 0..1. The denoiser trusts them.
  for (size_t p = 0; p < size_t(expected.area()) && guide_floats; ++p) {
    float g[kGuideFloats];
    std::memcpy(g, t.guides.data() + p * guide_floats * 4, guide_floats * 4);
    bool ok = std::isfinite(g[0]) && g[0] >= 0 && g[0] <= 1;  // kOpenGuides: the open fraction
    if (guide_floats == size_t(kGuideFloats)) {
      ok = true;
      for (int i = 0; i < kGuideFloats; ++i) ok = ok && std::isfinite(g[i]) && std::fabs(g[i]) <= 3.0e38f;
      ok = ok && (g[3] >= 0 || g[3] == -1.0f) && g[4] >= 0 && g[5] >= 0 && g[6] >= 0 && g[7] >= 0 && g[7] <= 1;
    }
    if (!ok) return "tile " + str(expected) + " with guides out of range";
  }
  // The packets the task covers (its pixel rectangle, rounded out to packets).
  const Rect want = pixels_to_packets(expected, layout);
  if (!t.sat.empty()) {
    std::string err;
    auto sat = Sat::try_deserialize(t.sat.data(), t.sat.size(), &err);
    if (!sat) return "cost SAT: " + err;
    if (!(sat->packets() == want) || !packet_space(width, height, layout).contains(sat->packets()))
      return "cost SAT over packets " + str(sat->packets()) + " for task packets " + str(want);
  }
  // Depths: one float per packet of the task, or none. Their values are not checked: the
  // tiler reads any float safely (lb/reproject.h, decode_depths).
  if (!t.depth.empty()) {
    if (t.depth.size() != size_t(want.area()) * 4)
      return "tile " + str(expected) + " with " + std::to_string(t.depth.size()) + " bytes of depths, expected " +
             std::to_string(size_t(want.area()) * 4);
  }
  return {};
}

namespace {
// A node or master name: 1..256 bytes, no control characters, quotes or backslashes.
bool usable_name(const std::string& name) {
  bool ok = !name.empty() && name.size() <= 256;
  for (unsigned char c : name) ok &= c >= 0x20 && c != 0x7f && c != '"' && c != '\\';
  return ok;
}
}  // namespace

std::string check_nodes(const std::vector<NodeInfo>& nodes) {
  if (nodes.size() > 65536) return std::to_string(nodes.size()) + " nodes";
  for (const NodeInfo& n : nodes) {
    if (!usable_name(n.name)) return "a node without a usable name";
    if (n.logical_cores < 1 || n.logical_cores > 65536)
      return "node " + n.name + " claims " + std::to_string(n.logical_cores) + " logical cores";
    if (!std::isfinite(n.single_core_perf) || n.single_core_perf <= 0 || n.single_core_perf > 1000)
      return "node " + n.name + " claims a single-core performance of " + std::to_string(n.single_core_perf);
  }
  return {};
}

Json nodes_value(const std::vector<NodeInfo>& nodes) {
  std::vector<Json> out;
  out.reserve(nodes.size());
  for (const NodeInfo& n : nodes)
    out.push_back(Json::object({{"name", n.name}, {"cores", n.logical_cores}, {"perf", Json::number(n.single_core_perf)}}));
  return Json::array(std::move(out));
}

std::string check_open(const OpenRequest& req) {
  if (req.session == 0) return "session 0";
  if (!usable_name(req.master)) return "a master name that is empty, longer than 256 bytes or not printable";
  auto pow2 = [](int32_t v) { return v >= 1 && v <= 16 && (v & (v - 1)) == 0; };
  const int64_t rays = int64_t(req.packet_w) * req.packet_h;
  if (!pow2(req.packet_w) || !pow2(req.packet_h) || (rays != 4 && rays != 8 && rays != 16))
    return "packet layout " + std::to_string(req.packet_w) + "x" + std::to_string(req.packet_h) +
           " (the ray tracer has 4, 8 or 16 rays per packet)";
  if (req.timeout_ms > 3'600'000) return "reply timeout of " + std::to_string(req.timeout_ms) + " ms";
  if (req.keepalive_ms < 10 || req.keepalive_ms > 60'000)
    return "keep-alive period of " + std::to_string(req.keepalive_ms) + " ms (10..60000)";
  return {};
}

std::string check_batch(const RenderBatch& b, const protocol::Limits& lim) {
  if (b.width < 1 || b.height < 1 || b.width > lim.max_width || b.height > lim.max_height)
    return "frame " + std::to_string(b.width) + "x" + std::to_string(b.height) + " outside 1x1.." +
           std::to_string(lim.max_width) + "x" + std::to_string(lim.max_height);
  if (b.ao_samples < 0 || uint32_t(b.ao_samples) > lim.max_ao_samples)
    return "ao_samples " + std::to_string(b.ao_samples) + " outside 0.." + std::to_string(lim.max_ao_samples);
  if (b.max_depth < 0 || uint32_t(b.max_depth) > lim.max_depth)
    return "max_depth " + std::to_string(b.max_depth) + " outside 0.." + std::to_string(lim.max_depth);
  if (b.renderer > uint8_t(protocol::RendererKind::rasterizer)) return "renderer kind " + std::to_string(int(b.renderer));
  if (b.radiance && b.renderer != uint8_t(protocol::RendererKind::raytracer))
    return "radiance asked of the rasterizer (progressive stills are ray traced)";
  if (b.guides > kOpenGuides) return "guides kind " + std::to_string(int(b.guides));
  if (b.guides != kNoGuides && !b.radiance) return "guides asked without radiance (they serve a refining still)";
  if (b.timeout_ms < 1 || b.timeout_ms > 3'600'000) return "timeout of " + std::to_string(b.timeout_ms) + " ms";
  if (b.tasks.size() > 65536) return std::to_string(b.tasks.size()) + " tasks";
  // Compared, not subtracted (Rect::width of a peer's [-2^31, 2^31) overflows): a task is empty
  // when it has no pixel, and else lies inside the frame.
  for (const Rect& t : b.tasks)
    if (t.x1 > t.x0 && t.y1 > t.y0 && !(t.x0 >= 0 && t.y0 >= 0 && t.x1 <= b.width && t.y1 <= b.height))
      return "task [" + std::to_string(t.x0) + "," + std::to_string(t.y0) + "," + std::to_string(t.x1) + "," +
             std::to_string(t.y1) + "] outside the frame " + std::to_string(b.width) + "x" + std::to_string(b.height);
  if (!b.plan.empty()) {
    if (!b.radiance) return "a plan of blocks for a frame that is no sample of a still";
    for (const Rect& t : b.tasks)
      if (std::string why = check_plan(b.plan_blocks, b.plan, b.width, b.height, t); !why.empty()) return why;
  }
  return {};
}

std::string apply_records(Scene& scene, const std::vector<uint8_t>& bytes, const protocol::Limits& node_limits) {
  if (bytes.empty()) return {};
  // The scene-level limits are this node's own; a forwarded message may be bigger than a
  // client's (a whole scene when a node joins), so the message-level ones are lifted.
  protocol::Limits lim = node_limits;
  lim.max_message_bytes = std::max<uint32_t>(lim.max_message_bytes, uint32_t(std::min<size_t>(bytes.size(), 0xffffffffu)));
  lim.max_records = 0xffffffffu;
  lim.max_message_payload_bytes = std::max<uint64_t>(lim.max_message_payload_bytes, lim.max_client_bytes);
  auto res = protocol::decode_client(bytes.data(), bytes.size(), lim);
  if (!res) return res.error().message;
  std::string first;
  for (auto& r : res.value()) {
    auto st = apply(scene, std::move(r), lim);
    if (!st && first.empty()) first = st.error().message;
  }
  return first;
}

}  // namespace tessera
