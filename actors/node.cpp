#include "actors/node.h"
#include "actors/checks.h"
#include "actors/errors.h"

#include <atomic>
#include <chrono>
#include <cstdint>
#include <condition_variable>
#include <cstdio>
#include <mutex>
#include <thread>
#ifdef __GLIBC__
#include <malloc.h>
#endif

#include <caf/all.hpp>

#include "protocol/scene_records.h"

namespace tessera {

std::vector<uint8_t> scene_snapshot_bytes(const SceneSnapshot& s) {
  if (!s.scene) return {};
  return protocol::encode(protocol::scene_to_records(*s.scene));
}

caf::error scene_snapshot_from_bytes(const std::vector<uint8_t>& bytes, SceneSnapshot& out) {
  auto scene = std::make_shared<Scene>();
  // The master validated the scene against its own limits already.
  std::string err = apply_records(*scene, bytes, protocol::Limits{});
  if (!err.empty()) return caf::make_error(caf::sec::invalid_argument, "scene snapshot: " + err);
  out.scene = std::move(scene);
  return caf::none;
}

int64_t steady_ns() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::steady_clock::now().time_since_epoch())
      .count();
}

void register_message_types(caf::actor_system_config& cfg) {
  // protocol::ErrorCode is CAF's error category "tessera" (actors/errors.h): sys.render(e)
  // names the code, and the message it carries.
  cfg.add_error_category(kErrorCategory, [](uint8_t code, caf::atom_value, const caf::message& ctx) {
    std::string s = std::string("tessera: ") + protocol::to_string(protocol::ErrorCode(code));
    if (ctx.match_elements<std::string>()) s += " (" + ctx.get_as<std::string>(0) + ")";
    return s;
  });
  cfg.add_message_type<Payload>("tessera::payload");  // not std::vector<uint8_t>: see BytesField
  cfg.add_message_type<SceneSnapshot>("tessera::scene_snapshot");
  cfg.add_message_type<RenderTask>("tessera::render_task");
  cfg.add_message_type<TileResult>("tessera::tile_result");
  cfg.add_message_type<TaskRequest>("tessera::task_request");
  cfg.add_message_type<TaskList>("tessera::task_list");
  cfg.add_message_type<SatReport>("tessera::sat_report");
  cfg.add_message_type<FrameStart>("tessera::frame_start");
  cfg.add_message_type<FrameTiles>("tessera::frame_tiles");
  cfg.add_message_type<EncodeJob>("tessera::encode_job");
  cfg.add_message_type<EncodedFrame>("tessera::encoded_frame");
  cfg.add_message_type<SessionStatus>("tessera::session_status");
  cfg.add_message_type<NodeInfo>("tessera::node_info");
  cfg.add_message_type<std::vector<NodeInfo>>("tessera::node_infos");
  cfg.add_message_type<RenderBatch>("tessera::render_batch");
  cfg.add_message_type<BatchReply>("tessera::batch_reply");
  cfg.add_message_type<OpenRequest>("tessera::open_request");
  cfg.add_message_type<OpenReply>("tessera::open_reply");
  cfg.add_message_type<ChildLink>("tessera::child_link");
  cfg.add_message_type<std::vector<ChildLink>>("tessera::child_links");
  cfg.add_message_type<std::vector<double>>("tessera::doubles");
}

std::string json_quote(const std::string& s) {
  static const char* hex = "0123456789abcdef";
  std::string o = "\"";
  o.reserve(s.size() + 2);
  const auto* b = reinterpret_cast<const unsigned char*>(s.data());
  const size_t n = s.size();
  for (size_t i = 0; i < n;) {
    const unsigned char c = b[i];
    if (c == '"' || c == '\\') {
      o += '\\';
      o += char(c);
      ++i;
    } else if (c < 0x20 || c == 0x7f) {
      o += "\\u00";
      o += hex[c >> 4];
      o += hex[c & 15];
      ++i;
    } else if (c < 0x80) {
      o += char(c);
      ++i;
    } else {
      // A well-formed UTF-8 sequence (no overlong forms, no surrogates, <= U+10FFFF) is kept.
      size_t len = c >= 0xc2 && c <= 0xdf ? 2 : c >= 0xe0 && c <= 0xef ? 3 : c >= 0xf0 && c <= 0xf4 ? 4 : 0;
      bool ok = len > 0 && i + len <= n;
      for (size_t k = 1; ok && k < len; ++k) ok = (b[i + k] & 0xc0) == 0x80;
      if (ok && len == 3) ok = !(c == 0xe0 && b[i + 1] < 0xa0) && !(c == 0xed && b[i + 1] >= 0xa0);
      if (ok && len == 4) ok = !(c == 0xf0 && b[i + 1] < 0x90) && !(c == 0xf4 && b[i + 1] >= 0x90);
      if (ok) {
        o.append(s, i, len);
        i += len;
      } else {
        o += "\\ufffd";
        ++i;
      }
    }
  }
  return o + "\"";
}

namespace {

// What the process holds beyond what its heap has in use: RSS less the allocator's live bytes
// (code, stacks and the like count too; only its change matters). -1 where it cannot be read.
int64_t heap_slack_bytes() {
#if defined(__GLIBC__) && (__GLIBC__ > 2 || (__GLIBC__ == 2 && __GLIBC_MINOR__ >= 33))
  long pages = 0, resident = 0;
  if (FILE* f = std::fopen("/proc/self/statm", "r")) {
    if (std::fscanf(f, "%ld %ld", &pages, &resident) != 2) resident = 0;
    std::fclose(f);
  }
  if (resident <= 0) return -1;
  const struct mallinfo2 mi = mallinfo2();
  return int64_t(resident) * 4096 - int64_t(mi.uordblks + mi.hblkhd);
#else
  return -1;
#endif
}

// The slack right after the last trim, lowered when freed memory is put back to use (the
// low-water mark): a rise above it is memory freed since, still resident.
std::atomic<int64_t> slack_mark{-1};

// One trimmer per process: a deadline that later calls push out, and a thread that waits for
// it, trims, and ends (so an idle node keeps no thread for it).
struct HeapTrimmer {
  std::mutex m;
  std::condition_variable cv;
  std::chrono::steady_clock::time_point due{};
  bool running = false;

  void schedule(uint32_t delay_ms) {
    std::lock_guard<std::mutex> l(m);
    due = std::chrono::steady_clock::now() + std::chrono::milliseconds(delay_ms);
    if (running) {
      cv.notify_one();
      return;
    }
    running = true;
    std::thread([this] { run(); }).detach();
  }
  void run() {
    std::unique_lock<std::mutex> l(m);
    while (std::chrono::steady_clock::now() < due) cv.wait_until(l, due);  // a later call moves `due`
    running = false;
    l.unlock();
#ifdef __GLIBC__
    malloc_trim(0);
#endif
    slack_mark = heap_slack_bytes();
  }
};

}  // namespace

void schedule_heap_trim(uint32_t delay_ms) {
  static HeapTrimmer* trimmer = new HeapTrimmer;  // never destroyed: its thread may outlive main
  trimmer->schedule(delay_ms);
}

bool trim_heap_if_regrown(int64_t regrow_bytes) {
  const int64_t slack = heap_slack_bytes(), mark = slack_mark;
  if (slack < 0) return false;
  if (mark >= 0 && slack - mark > regrow_bytes) {
    slack_mark = slack;  // one trim per rise, not one per tick until the trim has run
    schedule_heap_trim(0);
    return true;
  }
  if (mark < 0 || slack < mark) slack_mark = slack;
  return false;
}


}  // namespace tessera
