#pragma once
// What a node checks of what its peers send before it uses it: a child's tiles and node
// list, a parent's open requests and batches, forwarded scene records. Pure functions; each
// returns why the input cannot be used (empty string: it can).
#include <string>
#include <vector>

#include "actors/event.h"
#include "actors/cluster_protocol.h"
#include "core/rect.h"
#include "core/scene.h"
#include "lb/tiler.h"
#include "protocol/protocol.h"

namespace tessera {

// A tile a node returned: `expected` is the task that was sent; pixels and SAT must match it.
std::string check_tile(const TileResult& t, uint32_t frame, const Rect& expected, PacketLayout layout, int32_t width,
                       int32_t height, bool radiance = false, uint8_t guides = kNoGuides);

// A sub-tree's node list: every node needs a name, 1..65536 logical cores and a finite
// single-core performance in (0, 1000].
std::string check_nodes(const std::vector<NodeInfo>& nodes);

// A node list as a JSON array of {"name", "cores", "perf"}, for events.
Json nodes_value(const std::vector<NodeInfo>& nodes);

// A peer's open request: a session id, a master name like a node name (1..256 bytes, no
// control characters, quotes or backslashes), a packet layout the ray tracer has (w and h
// powers of two, 4, 8 or 16 rays), a reply timeout of at most an hour and a keep-alive
// period of 10 ms..60 s.
std::string check_open(const OpenRequest& req);

// A batch from a worker's parent, by the rules that apply to a client's requests on this
// node: the frame within the limits' max_width x max_height, ao_samples and max_depth within
// max_ao_samples and max_depth, a known renderer kind, a timeout of 1 ms..1 h, and every task
// inside the frame. (The task count is checked against the node list by the subtree.)
std::string check_batch(const RenderBatch& b, const protocol::Limits& limits);

// The task of one node in a batch (with its part of the batch's plan of blocks).
RenderTask task_of(const RenderBatch& b, const Rect& pixels);

// A plan of blocks (RenderTask::plan, adaptive refinement) over `blocks`: one entry a block,
// inside the frame's blocks, covering the blocks of `pixels` (empty: no task). Empty plans pass.
std::string check_plan(const Rect& blocks, const std::vector<uint32_t>& plan, int32_t width, int32_t height,
                       const Rect& pixels);
// The part of a plan over `blocks` that covers `to` (in blocks, inside `blocks`).
std::vector<uint32_t> crop_plan(const Rect& blocks, const std::vector<uint32_t>& plan, const Rect& to);

// Applies encoded client records (a forwarded update or a snapshot) to a scene; validates
// them against this node's limits. Returns an error message, empty on success.
std::string apply_records(Scene& scene, const std::vector<uint8_t>& bytes, const protocol::Limits& limits);

}  // namespace tessera
