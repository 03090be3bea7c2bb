// Frame actor (frame_protocol.h): tiler -> root subtree -> recovery -> display, one frame at a time.
#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstring>
#include <memory>
#include <stdexcept>

#include <caf/all.hpp>

#include "actors/checks.h"
#include "actors/errors.h"
#include "actors/node.h"
#include "lb/sat.h"
#include "renderer/adaptive.h"
#include "renderer/denoise.h"
#include "renderer/renderer.h"

namespace tessera {
namespace {

using protocol::ErrorCode;
using denoise_atom = caf::atom_constant<caf::atom("denoise")>;

// A still being denoised (FrameStart::denoise): its first sample's guides and the open
// fractions of all its samples, beside the average (frame_state::acc). While it is denoised,
// every round renders every pixel (AdaptiveStill::set_uniform).
struct Denoising {
  bool on = false;             // later samples bring their open fractions: off once the plain
                               // average's estimate passed NodeSettings::denoise_below_db
  std::vector<float> guides;   // kGuideFloats a pixel, of sample 0
  StillAo ao;
  uint32_t shown = 0;          // the samples of the last frame shown
};

// What the denoising worker gets (the still's state, moved in and back) and gives.
struct DenoiseJob {
  AdaptiveStill acc;
  std::unique_ptr<Denoising> dn;
  double below_db = 0;
  Image image;          // the frame shown: denoised, or the plain average
  double estimate_db = 0, ms = 0;
  bool denoised = false;
  bool stopped = false;  // the frame was abandoned while it was denoised (`stop` raised)
  std::shared_ptr<std::atomic<bool>> stop = std::make_shared<std::atomic<bool>>(false);
  std::string error;
};

// Runs on the worker: estimates the plain average's PSNR and denoises below the threshold.
void run_denoise(DenoiseJob& j) {
  const auto t0 = std::chrono::steady_clock::now();
  try {
    DenoiseOptions options;
    options.stop = j.stop.get();
    DenoisedStep step = denoise_step(j.acc, j.dn->guides, j.dn->ao, j.below_db, options);
    j.image = std::move(step.image);
    j.estimate_db = step.estimate_db;
    j.denoised = step.denoised;
    j.stopped = step.stopped;
  } catch (const std::exception& e) {
    j.error = e.what();
  }
  j.ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
}

struct frame_state {
  std::shared_ptr<const NodeSettings> settings;
  uint64_t id = 0;
  PacketLayout layout;
  bool cluster = false;         // this process has a node actor: per-node figures in the log
  FrameActors a;
  uint32_t max_nodes = 0;
  std::vector<NodeInfo> nodes;  // the root subtree's committed list
  std::vector<size_t> used;     // the entries of `nodes` this client renders on
  bool listed = false;          // `nodes` holds a list
  bool recommit = true;         // the last batch reported a membership change: ask the root again
  std::shared_ptr<const Scene> sent;  // the scene the root subtree was given last
  // The frame in flight.
  FrameStart cur;
  RenderBatch batch;            // its settings and one task per node
  caf::typed_response_promise<uint32_t> done;
  uint32_t recovered = 0;       // tasks of lost nodes rendered here
  TaskList tiling;              // how its tasks were made (predictor, reprojection), without the tasks
  double last_rendering_ms = 0;
  // The progressive still's average (FrameStart::refine): the tiles' radiance of every sample
  // since its sample 0, composed here, where the tiles of all nodes meet; refined adaptively
  // (renderer/adaptive.h) after its first samples when adaptive_rounds().
  AdaptiveStill acc;
  std::unique_ptr<Denoising> dn;  // FrameStart::denoise: the still's denoising (none: plain)
  std::shared_ptr<std::atomic<bool>> denoise_stop;  // the denoising in flight stops when raised (cancel)
  uint32_t cancelled = 0;       // the last frame the session abandoned (cancel)
  int64_t cancelled_ns = 0;     // when its notice came (steady_ns)
  static inline const char* name = "tessera.frame";
};
using self_ptr = frame_actor::stateful_pointer<frame_state>;

// Whether this session's stills refine adaptively: the node's setting, with packets that tile a
// plan block (any the ray tracer detects does).
bool adaptive_rounds(const frame_state& st) {
  return st.settings->adaptive_round > 0 && kPlanBlock % st.layout.w == 0 && kPlanBlock % st.layout.h == 0;
}

// Whether the still's next round renders every block: without adaptive rounds, and while it is
// denoised (the denoiser needs every pixel's samples).
bool uniform_round(const frame_state& st) { return !adaptive_rounds(st) || (st.dn && st.dn->on); }

void log(self_ptr self, Event e) {
  e.scope = {{"session", self->state.id}};
  node_log(*self->state.settings, std::move(e));
}


// The committed node list: pick the nodes this client may use (the strongest first, at most
// max_nodes) and give their coefficients to the tiler.
void on_nodes(self_ptr self, std::vector<NodeInfo> nodes) {
  auto& st = self->state;
  std::vector<size_t> order(nodes.size());
  for (size_t i = 0; i < order.size(); ++i) order[i] = i;
  auto coef = [&](size_t i) { return double(nodes[i].logical_cores) * nodes[i].single_core_perf; };
  std::stable_sort(order.begin(), order.end(), [&](size_t a, size_t b) { return coef(a) > coef(b); });
  if (st.max_nodes > 0 && order.size() > st.max_nodes) order.resize(st.max_nodes);
  std::sort(order.begin(), order.end());  // keep list order (depth first) for the tiling
  std::vector<double> coefficients;
  for (size_t i : order) coefficients.push_back(std::max(1e-6, coef(i)));
  bool same = st.listed && nodes.size() == st.nodes.size() && order == st.used;
  for (size_t i = 0; same && i < nodes.size(); ++i)
    same = nodes[i].name == st.nodes[i].name && coef(i) == double(st.nodes[i].logical_cores) * st.nodes[i].single_core_perf;
  if (same) return;  // the root answered with the list it had
  st.listed = true;
  st.nodes = std::move(nodes);
  st.used = std::move(order);
  if (!coefficients.empty()) self->send(st.a.tiler, nodes_atom::value, std::move(coefficients));
  log(self, Event(Ev::nodes, nodes_value(st.nodes)).with("used", st.used.size()));
}

// Renders a task on this node's renderer: the tasks of lost nodes.
void render_here(self_ptr self, const RenderTask& t, std::function<void(TileResult&&)> cb) {
  auto& st = self->state;
  if (!st.a.renderer) {
    st.a.renderer = spawn_renderer(self->system(), st.layout, st.settings->detached);
    self->link_to(st.a.renderer);
  }
  self->request(st.a.renderer, caf::infinite, render_atom::value, st.cur.scene, t)
      .then([cb](TileResult& r) { cb(std::move(r)); },
            [cb, t](caf::error& e) { cb(failed_tile(t, e, ErrorCode::render_failed)); });
}

// Answers the session for the frame in flight: an error, or its tiles (`show`: sent to the
// display; a still's sample that is averaged and not shown sends nothing).
// The answer is whether the still wants more rounds: 0 once a refining still is converged
// (the next plan renders nothing), else 1.
void deliver(self_ptr self, std::vector<TileResult>&& shown, const std::string& error, bool show = true) {
  auto& st = self->state;
  auto done = std::move(st.done);
  st.cur.scene = {};  // the sync actor may change its scene once it has the answer
  if (!error.empty()) {
    done.deliver(protocol::make_error(ErrorCode::render_failed,
                                      "frame " + std::to_string(st.cur.meta.client_frame) + ": " + error));
    return;
  }
  if (st.cur.refine && st.acc.rounds() > 0 && st.acc.rounds() == st.cur.sample + 1) {  // this frame's round is in
    st.acc.set_uniform(uniform_round(st));
    st.acc.plan();
    st.cur.meta.converged = st.acc.converged();
  }
  if (show) self->send(st.a.display, display_atom::value, FrameTiles{st.cur.meta, std::move(shown)});
  done.deliver(st.cur.meta.converged ? 0u : 1u);
}

TileResult whole_frame(const FrameMeta& meta, Image&& image) {
  TileResult whole;
  whole.frame = meta.seq;
  whole.pixels = Rect{0, 0, meta.width, meta.height};
  whole.rgba = std::move(image.rgba);
  return whole;
}

// Adds the frame's tiles to the still's average, and their guides to its denoising.
void add_sample(self_ptr self, const std::vector<TileResult>& tiles) {
  auto& st = self->state;
  const FrameMeta& meta = st.cur.meta;
  const int32_t W = meta.width, H = meta.height;
  if (st.cur.sample == 0) {
    AdaptiveOptions options;
    if (adaptive_rounds(st)) options.round_cost = st.settings->adaptive_round;
    st.acc.reset(W, H, st.cur.scene.scene->environment().linear, std::max<uint32_t>(1, st.cur.target), options);
    st.acc.set_uniform(!adaptive_rounds(st));
    st.dn.reset();
    if (st.batch.guides == kAllGuides) {
      st.dn = std::make_unique<Denoising>();
      st.dn->on = true;
      st.dn->guides.assign(size_t(W) * size_t(H) * kGuideFloats, 0.0f);
      st.dn->ao.reset(W, H);
    }
  } else if (st.acc.rounds() != st.cur.sample || st.acc.width() != W || st.acc.height() != H) {
    throw std::logic_error("sample " + std::to_string(st.cur.sample) + " of a still that has " +
                           std::to_string(st.acc.rounds()));
  }
  for (const TileResult& t : tiles) {
    if (t.pixels.empty()) continue;
    st.acc.add_tile_bytes(t.radiance, t.pixels);
    if (!adaptive_rounds(st) || t.sat.empty()) continue;
    // Its packets' costs steer the next plans.
    const Sat sat = Sat::deserialize(t.sat);
    CostMap cost;
    cost.packets = sat.packets();
    cost.cost.reserve(size_t(cost.packets.area()));
    for (int32_t py = cost.packets.y0; py < cost.packets.y1; ++py)
      for (int32_t px = cost.packets.x0; px < cost.packets.x1; ++px)
        cost.cost.push_back(uint32_t(std::min<uint64_t>(sat.cost({px, py, px + 1, py + 1}), 0xFFFFFFFFu)));
    st.acc.add_cost(cost, st.layout);
  }
  st.acc.end_round();
  if (!st.dn || st.batch.guides == kNoGuides) return;
  // The tiles' guides into the frame's: all of them (sample 0), or the open fractions.
  const size_t floats = st.batch.guides == kAllGuides ? size_t(kGuideFloats) : 1;
  std::vector<float> open;
  if (floats == 1) open.assign(size_t(W) * size_t(H), 1.0f);
  float* dst = floats == 1 ? open.data() : st.dn->guides.data();
  for (const TileResult& t : tiles) {
    const Rect& r = t.pixels;
    if (!Rect{0, 0, W, H}.contains(r) || t.guides.size() != size_t(r.area()) * floats * sizeof(float))
      throw std::logic_error("a tile without the guides of its pixels");
    const size_t row = size_t(r.width()) * floats;
    for (int32_t y = r.y0; y < r.y1; ++y)
      std::memcpy(dst + (size_t(y) * size_t(W) + size_t(r.x0)) * floats,
                  t.guides.data() + size_t(y - r.y0) * row * sizeof(float), row * sizeof(float));
  }
  if (floats == 1)
    st.dn->ao.add_open(open);
  else
    st.dn->ao.add(st.dn->guides);
}

void abandon(self_ptr self, const std::vector<TileResult>& tiles, const char* stage);

// Estimates and denoises the still's average on a worker of its own (it takes about as long as
// a sample, and would hold one of CAF's few scheduler threads), then shows the frame. The
// still's state moves into the job and back: the session starts no frame before this one is
// answered.
void denoise_and_show(self_ptr self) {
  auto& st = self->state;
  auto job = std::make_shared<DenoiseJob>();
  job->acc = std::move(st.acc);
  job->dn = std::move(st.dn);
  job->below_db = st.settings->denoise_below_db;
  st.denoise_stop = job->stop;
  auto work = [job](caf::event_based_actor* a) -> caf::behavior {
    return {[=](denoise_atom) {
      a->quit();
      run_denoise(*job);
      return true;
    }};
  };
  // Deterministic tests run every actor on the test scheduler.
  auto worker = st.settings->detached ? self->spawn<caf::detached + caf::hidden>(work) : self->spawn<caf::hidden>(work);
  auto back = [self, job](std::string error) {
    auto& st = self->state;
    st.acc = std::move(job->acc);
    st.dn = std::move(job->dn);
    st.denoise_stop.reset();
    FrameMeta& meta = st.cur.meta;
    if (error.empty()) error = job->error;
    // Abandoned while it was denoised: the sample is in the average, its picture is not shown.
    if (error.empty() && job->stopped && st.dn) return abandon(self, {}, "denoising");
    if (!error.empty() || !st.dn) {  // a fault of this node, not the client's: the still goes on plainly
      log(self, Event(Ev::error, "denoising failed, the still is averaged plainly: " + error));
      st.dn.reset();
      job->image = st.acc.average();
    } else {
      meta.estimated_db = job->estimate_db;
      meta.denoised = job->denoised;
      meta.denoise_ms = job->ms;
      st.dn->shown = st.acc.rounds();
      if (!job->denoised) st.dn->on = false;  // past the threshold: plain from now on, no more guides
    }
    deliver(self, {whole_frame(meta, std::move(job->image))}, {});
  };
  self->request(worker, caf::infinite, denoise_atom::value)
      .then([back](bool) { back({}); }, [back](caf::error&) { back("the denoising worker ended"); });
}

void finish_frame(self_ptr self, std::vector<TileResult>&& tiles, std::vector<double>&& perf) {
  auto& st = self->state;
  FrameMeta& meta = st.cur.meta;
  meta.render_end_ns = steady_ns();
  std::string error;
  SatReport rep{meta.seq, meta.width, meta.height, st.layout.w, st.layout.h, {}, {}, {}, {}, !st.batch.plan.empty()};
  if (st.batch.hit_points && st.cur.scene.scene) rep.camera = pack_camera(st.cur.scene.scene->camera());
  std::vector<TileResult> shown;
  std::vector<Json> per_node;
  double max_norm = 0, sum_norm = 0;
  size_t rendered = 0;
  for (size_t i = 0; i < tiles.size(); ++i) {
    auto& tile = tiles[i];
    if (tile.pixels.empty() && !tile.failed()) continue;  // a node without a task this frame
    meta.kernel_ms += tile.kernel_ms;
    meta.rendering_ms = std::max(meta.rendering_ms, tile.rendering_ms);
    meta.sat_ms = std::max(meta.sat_ms, tile.sat_ms);
    if (tile.failed()) error = std::string(to_string(tile.code)) + ": " + tile.error;
    if (i < st.nodes.size() && st.cluster) {  // a cluster node: per-node figures
      const NodeInfo& n = st.nodes[i];
      const double norm = tile.kernel_ms / std::max(1e-9, double(n.logical_cores));
      max_norm = std::max(max_norm, norm);
      sum_norm += norm;
      ++rendered;
      per_node.push_back(Json::object({{"node", i},
                                       {"kernel_ms", Json::number(tile.kernel_ms)},
                                       {"rendering_ms", Json::number(tile.rendering_ms)},
                                       {"pixels", static_cast<long long>(tile.pixels.area())}}));
    }
    rep.sats.push_back(std::move(tile.sat));
    rep.depths.push_back(std::move(tile.depth));
    rep.perf.push_back(i < perf.size() ? perf[i] : 1.0);
    shown.push_back(std::move(tile));
  }
  self->send(st.a.tiler, sats_atom::value, std::move(rep));
  st.last_rendering_ms = meta.rendering_ms;
  if (!per_node.empty()) {
    const double balance = rendered && sum_norm > 0 ? max_norm / (sum_norm / double(rendered)) : 1.0;
    log(self, Event(Ev::cluster_frame, meta.client_frame)
                  .with("balance", Json::number(balance, 4))
                  .with("predictor", to_string(Predictor(st.tiling.predictor)))
                  .with("reproject_ms", Json::number(st.tiling.reproject_ms))
                  .with("reproject_cpu_ms", Json::number(st.tiling.reproject_cpu_ms))
                  .with("filled", static_cast<long long>(st.tiling.filled))
                  .with("recovered", st.recovered)
                  .with("per_node", Json::array(std::move(per_node))));
  }
  if (error.empty() && st.cur.refine) {
    // The still's average (while it is denoised, the denoised average) replaces the sample's
    // own pixels.
    try {
      add_sample(self, shown);
      // Samples per pixel: the rounds while every pixel renders each round, else the work done
      // in whole samples (the mean over the pixels, rounded down).
      meta.samples = uint32_t(std::max(1.0, std::floor(st.acc.mean_samples() + 1e-9)));
      meta.round = st.acc.rounds();
      meta.blocks = st.batch.plan.empty() ? 0 : uint32_t(st.acc.planned());
      if (st.dn && st.dn->on && st.acc.rounds() >= 2) {
        if (shown_while_denoising(st.acc.rounds(), st.dn->shown, st.cur.target)) return denoise_and_show(self);
        return deliver(self, {}, {}, false);  // averaged, shown with a later sample
      }
      shown.clear();
      shown.push_back(whole_frame(meta, st.acc.average()));
      if (st.dn) st.dn->shown = st.acc.rounds();
    } catch (const std::exception& e) {
      error = std::string("refine: ") + e.what();
      st.acc = AdaptiveStill{};
      st.dn.reset();
    }
  }
  deliver(self, std::move(shown), error);
}

// The frame in flight was abandoned (cancel): answered, and nothing of it averaged, shown or
// given to the tiler (whose next tasks come from the last complete frame's SATs).
// `stage`: where the frame was when it was abandoned: tiling, rendering, or denoising (then
// the sample is already in the average and its SATs with the tiler; only its picture is not
// shown).
void abandon(self_ptr self, const std::vector<TileResult>& tiles, const char* stage) {
  auto& st = self->state;
  size_t stopped = 0;
  double rendering_ms = 0;
  for (const TileResult& t : tiles) {
    stopped += t.cancelled;
    rendering_ms = std::max(rendering_ms, t.rendering_ms);
  }
  log(self, Event(Ev::abandoned, st.cur.meta.client_frame)
                .with("sample", st.cur.sample)
                .with("stage", stage)
                .with("tiles_stopped", static_cast<long long>(stopped))
                .with("rendering_ms", Json::number(rendering_ms))
                .with("stop_ms", Json::number(double(steady_ns() - st.cancelled_ns) / 1e6)));
  deliver(self, {}, {}, false);
}

// Tasks whose node failed (down, too late, impossible tiles) are rendered here, so the frame
// still completes; the root subtree commits its list again before the next frame.
void recover(self_ptr self, BatchReply&& r) {
  auto& st = self->state;
  const std::vector<Rect>& tasks = st.batch.tasks;
  if (r.changed) st.recommit = true;
  // A tile that stopped early belongs to a frame its session abandoned, which ends here if any
  // of its tiles stopped or failed (its lost tasks are not rendered again); one complete by then
  // goes on as usual. In any other frame such a tile is a node's fault.
  const bool abandoned = st.cancelled == st.cur.meta.seq;
  bool incomplete = false;
  for (TileResult& t : r.tiles) {
    incomplete = incomplete || t.failed() || t.cancelled;
    if (t.cancelled && !t.failed() && !abandoned) {
      t.code = ErrorCode::bad_tile;
      t.error = "a tile that stopped early in a frame nobody abandoned";
    }
  }
  if (abandoned && incomplete) return abandon(self, r.tiles, "rendering");
  std::vector<size_t> lost;
  for (size_t i = 0; i < r.tiles.size() && i < tasks.size(); ++i)
    if (r.tiles[i].failed() && !tasks[i].empty()) lost.push_back(i);
  std::vector<double> perf(r.tiles.size(), 1.0);
  for (size_t i = 0; i < r.tiles.size() && i < st.nodes.size(); ++i) perf[i] = st.nodes[i].single_core_perf;
  if (lost.empty()) return finish_frame(self, std::move(r.tiles), std::move(perf));
  std::vector<Json> errors;
  for (size_t i : lost) errors.push_back(Json::object({{"code", to_string(r.tiles[i].code)}, {"message", r.tiles[i].error}}));
  log(self, Event(Ev::recovering, lost.size())
                .with("frame", st.cur.meta.client_frame)
                .with("errors", Json::array(std::move(errors))));
  st.recovered = uint32_t(lost.size());
  auto tiles = std::make_shared<std::vector<TileResult>>(std::move(r.tiles));
  auto perfs = std::make_shared<std::vector<double>>(std::move(perf));
  auto left = std::make_shared<size_t>(lost.size());
  const uint32_t seq = st.cur.meta.seq;
  for (size_t i : lost) {
    (*perfs)[i] = st.settings->coefficient.single_core_perf;
    render_here(self, task_of(st.batch, tasks[i]), [self, seq, i, tiles, perfs, left](TileResult&& res) {
      (*tiles)[i] = std::move(res);
      if (--*left > 0 || self->state.cur.meta.seq != seq) return;
      finish_frame(self, std::move(*tiles), std::move(*perfs));
    });
  }
}

void render_batch(self_ptr self) {
  auto& st = self->state;
  const FrameMeta& meta = st.cur.meta;
  RenderBatch& batch = st.batch;
  batch = RenderBatch{};
  batch.frame = meta.seq;
  batch.width = meta.width;
  batch.height = meta.height;
  batch.ao_samples = st.cur.ao_samples;
  batch.max_depth = st.cur.max_depth;
  batch.renderer = st.cur.renderer;
  batch.sample = st.cur.sample;
  batch.seed = st.cur.seed;
  batch.radiance = st.cur.refine;
  // A denoised still: sample 0 brings all the guides, the later ones their open fractions until
  // the estimate passes the threshold.
  batch.guides = !st.cur.refine || !st.cur.denoise ? kNoGuides
                 : st.cur.sample == 0              ? kAllGuides
                 : st.dn && st.dn->on              ? kOpenGuides
                                                   : kNoGuides;
  // A still's later rounds: the blocks its plan renders (renderer/adaptive.h), each at its own
  // sample; no plan while every block renders this round's sample.
  if (st.cur.refine && st.cur.sample > 0 && st.acc.rounds() == st.cur.sample) {
    st.acc.set_uniform(uniform_round(st));
    const std::vector<uint32_t>& plan = st.acc.plan();
    if (st.acc.converged()) {  // nothing left to render (the session asked once too often)
      st.cur.meta.converged = true;
      return deliver(self, {}, {}, false);
    }
    if (!std::all_of(plan.begin(), plan.end(), [&](uint32_t k) { return k == st.cur.sample; })) {
      batch.plan = plan;
      batch.plan_blocks = st.acc.blocks();
    }
  }
  // The balancer's reprojection needs each packet's depth, which only the ray tracer gives.
  batch.hit_points = st.settings->reproject && st.cur.renderer == 0;
  // Bounded delay for lost nodes: the configured timeout, or 3x the last frame if longer.
  batch.timeout_ms = std::max<uint32_t>(st.settings->task_timeout_ms, uint32_t(3 * st.last_rendering_ms + 200));
  batch.tasks.assign(st.nodes.size(), Rect{});
  if (st.used.empty()) {
    // No rendering node at all (a dedicated master whose children are all gone): render the
    // whole frame here rather than show nothing.
    batch.tasks = {Rect{0, 0, meta.width, meta.height}};
    BatchReply r;
    r.tiles = {failed_tile(task_of(batch, batch.tasks[0]), ErrorCode::no_node, "no rendering node")};
    return recover(self, std::move(r));
  }
  TaskRequest req{meta.seq, meta.width, meta.height, st.layout.w, st.layout.h, {}, !batch.plan.empty()};
  if (batch.hit_points && st.cur.scene.scene) req.camera = pack_camera(st.cur.scene.scene->camera());
  self->request(st.a.tiler, caf::infinite, tasks_atom::value, req).then([=](TaskList& tl) {
    auto& st = self->state;
    if (st.cancelled == st.cur.meta.seq) return abandon(self, {}, "tiling");  // before it began
    st.cur.meta.tiling_ms = tl.tiling_ms;
    for (size_t k = 0; k < tl.tasks.size() && k < st.used.size(); ++k) st.batch.tasks[st.used[k]] = tl.tasks[k];
    tl.tasks.clear();  // copied into the batch; the rest says how they were made
    st.tiling = std::move(tl);
    st.cur.meta.nodes = uint32_t(st.used.size());
    if (st.cur.scene.scene != st.sent) {  // the session's scene object (changed in place between frames)
      st.sent = st.cur.scene.scene;
      self->send(st.a.subtree, scene_atom::value, st.cur.scene);
    }
    self->request(st.a.subtree, caf::infinite, render_atom::value, st.batch)
        .then([=](BatchReply& r) { recover(self, std::move(r)); },
              [=](caf::error& e) {
                auto& st = self->state;
                BatchReply r;
                r.changed = true;
                for (const Rect& t : st.batch.tasks) r.tiles.push_back(failed_tile(task_of(st.batch, t), e, ErrorCode::node_lost));
                recover(self, std::move(r));
              });
  });
}

frame_actor::behavior_type frame_impl(self_ptr self, std::shared_ptr<const NodeSettings> settings, uint64_t id,
                                      PacketLayout layout, FrameActors actors) {
  auto& st = self->state;
  st.settings = std::move(settings);
  st.id = id;
  st.layout = layout;
  st.cluster = bool(st.settings->node.lock());
  st.a = std::move(actors);
  return {
      [=](nodes_atom, uint32_t max_nodes) -> caf::result<uint32_t> {
        self->state.max_nodes = max_nodes;
        auto rp = self->make_response_promise<uint32_t>();
        self->request(self->state.a.subtree, caf::infinite, nodes_atom::value)
            .then(
                [=](std::vector<NodeInfo>& nodes) mutable {
                  on_nodes(self, std::move(nodes));
                  self->state.recommit = false;
                  rp.deliver(uint32_t(std::max<size_t>(1, self->state.used.size())));
                },
                [=](caf::error& e) mutable { rp.deliver(std::move(e)); });
        return rp;
      },
      [=](cancel_atom, uint32_t seq) {
        auto& st = self->state;
        // Only the still's sample in flight: a requested frame is always answered with its
        // picture, and a notice for a frame already answered changes nothing.
        if (seq != st.cur.meta.seq || !st.cur.meta.refined || !st.done.pending() || st.cancelled == seq) return;
        st.cancelled = seq;
        st.cancelled_ns = steady_ns();
        if (st.denoise_stop) st.denoise_stop->store(true, std::memory_order_relaxed);  // rendered, being denoised
        self->send(st.a.subtree, cancel_atom::value, seq);
      },
      [=](render_atom, FrameStart& fs) -> caf::result<uint32_t> {
        auto& st = self->state;
        st.cur = std::move(fs);
        st.recovered = 0;
        st.done = self->make_response_promise<uint32_t>();
        // Membership changes (lost nodes, nodes that joined) are committed between frames,
        // after a batch whose reply says the tree changed (a root sets `changed` when a child
        // failed or joined); otherwise the committed list stands.
        if (!st.recommit) {
          render_batch(self);
          return st.done;
        }
        st.recommit = false;
        self->request(st.a.subtree, caf::infinite, nodes_atom::value)
            .then(
                [=](std::vector<NodeInfo>& nodes) {
                  on_nodes(self, std::move(nodes));
                  render_batch(self);
                },
                [=](caf::error& e) { self->state.done.deliver(std::move(e)); });
        return self->state.done;
      },
  };
}

}  // namespace

frame_actor spawn_frame(caf::actor_system& sys, std::shared_ptr<const NodeSettings> settings, uint64_t session_id,
                        PacketLayout layout, FrameActors actors) {
  return sys.spawn(frame_impl, std::move(settings), session_id, layout, std::move(actors));
}

}  // namespace tessera
