// tessera soak [--topology single|cluster] [--seconds S] [--clients N] [--scene S.gltf --camera-loop L.json]
//              [--size W H] [--frames-per-session F] [--alone-seconds A] [--drain-seconds D]
//              [--rss-tolerance-mb M] [--rss-tolerance-pct P] [--thread-tolerance T] [--threads T]
//              [--malformed all|safe] [--reader-size W H] [--binary PATH] [--trim-probe] [--full-drain]
// The robustness soak (issue 16's proof). Starts the nodes itself as child processes of this
// binary (`tessera serve` on port 0; one node, or a dedicated master with two workers), then:
//   warm-up   one ordinary session, then one client alone streaming for A seconds (its fps);
//   baseline  RSS and thread count of every node process once the warm-up session has gone;
//   churn     S seconds of N clients: N-2 well-behaved clients that connect, handshake, upload
//             the scene, render F frames along the camera loop and disconnect, over and over;
//             one client that sends malformed messages all the time (reconnecting when closed)
//             and counts the error replies; one client that never reads its socket (a raw TCP
//             WebSocket upgrade by hand, then a handshake and render requests);
//   drain     the well-behaved and malformed clients stop; the never-reader stays connected;
//             every process must come back within the tolerance of its baseline (the queue of a
//             client that does not read must not hold the node's memory);
//   final     the never-reader goes; the same check again.
// Every node process's RSS and threads (/proc/PID/status) are sampled once a second and printed
// as JSON lines; the last line is the summary ("summary": true). Exit status: 0 when every node
// lived and came back to baseline, 1 when a node died or a process stayed above its tolerance
// (or the well-behaved clients got no frame), 2 when the nodes could not be started.
#include <arpa/inet.h>
#include <fcntl.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <signal.h>
#include <sys/prctl.h>
#include <sys/socket.h>
#include <sys/utsname.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <limits>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <random>
#include <sstream>
#include <thread>

#include "app/command.h"
#include "app/common.h"
#include "protocol/protocol.h"
#include "protocol/scene_records.h"
#include "net/ws_client.h"
#include "net/ws_frame.h"
#include "renderer/raytracer.h"

namespace tessera::app {
namespace {

using Clock = std::chrono::steady_clock;
using protocol::ClientRecord;

double since(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }
void sleep_ms(int ms) { std::this_thread::sleep_for(std::chrono::milliseconds(ms)); }

// ---------------------------------------------------------------------------------------
// A node process: this binary's `serve`, stdout and stderr into unlinked temporary files (a
// chatty node never blocks on a pipe), killed with us (PR_SET_PDEATHSIG) if we die first.

class NodeProcess {
 public:
  NodeProcess(std::string name, const std::string& binary, const std::vector<std::string>& args)
      : name_(std::move(name)) {
    char out_name[] = "/tmp/tessera-soak-out-XXXXXX", err_name[] = "/tmp/tessera-soak-err-XXXXXX";
    const int out_w = mkstemp(out_name), err_w = mkstemp(err_name);
    if (out_w < 0 || err_w < 0) throw std::runtime_error("cannot create temporary files for " + name_);
    out_ = open(out_name, O_RDONLY);
    err_ = open(err_name, O_RDONLY);
    unlink(out_name);
    unlink(err_name);
    std::vector<std::string> full{binary, "serve"};
    full.insert(full.end(), args.begin(), args.end());
    for (auto& a : full) command_ += (command_.empty() ? "" : " ") + a;
    const pid_t parent = getpid();
    pid_ = fork();
    if (pid_ < 0) throw std::runtime_error("fork failed");
    if (pid_ == 0) {
      prctl(PR_SET_PDEATHSIG, SIGKILL);
      if (getppid() != parent) _exit(126);
      dup2(out_w, 1);
      dup2(err_w, 2);
      close(out_w);
      close(err_w);
      std::vector<char*> argv;
      for (auto& a : full) argv.push_back(const_cast<char*>(a.c_str()));
      argv.push_back(nullptr);
      execv(argv[0], argv.data());
      _exit(127);
    }
    close(out_w);
    close(err_w);
  }
  ~NodeProcess() {
    if (pid_ > 0 && !status_) {
      kill(pid_, SIGKILL);
      waitpid(pid_, nullptr, 0);
    }
    close(out_);
    close(err_);
  }
  NodeProcess(const NodeProcess&) = delete;
  NodeProcess& operator=(const NodeProcess&) = delete;

  const std::string& name() const { return name_; }
  const std::string& command() const { return command_; }
  pid_t pid() const { return pid_; }

  std::optional<std::string> first_line(int timeout_ms) {
    const auto deadline = Clock::now() + std::chrono::milliseconds(timeout_ms);
    while (Clock::now() < deadline) {
      pump();
      auto nl = stdout_.find('\n');
      if (nl != std::string::npos) return stdout_.substr(0, nl);
      if (!alive()) return std::nullopt;
      sleep_ms(20);
    }
    return std::nullopt;
  }
  bool alive() {
    std::lock_guard<std::mutex> l(mu_);
    if (status_) return false;
    int st = 0;
    if (waitpid(pid_, &st, WNOHANG) == pid_) {
      status_ = st;
      died_at_ = Clock::now();
      return false;
    }
    return true;
  }
  // "exit 0", "signal 6 (Aborted)", or "" while it runs.
  std::string how_it_ended() {
    std::lock_guard<std::mutex> l(mu_);
    if (!status_) return "";
    if (WIFEXITED(*status_)) return "exit " + std::to_string(WEXITSTATUS(*status_));
    if (WIFSIGNALED(*status_))
      return "signal " + std::to_string(WTERMSIG(*status_)) + " (" + strsignal(WTERMSIG(*status_)) + ")";
    return "status " + std::to_string(*status_);
  }
  std::optional<Clock::time_point> died_at() {
    std::lock_guard<std::mutex> l(mu_);
    return died_at_;
  }
  // SIGTERM, then SIGKILL after timeout_ms. True when it ended by itself within the time.
  bool stop(int timeout_ms) {
    if (!alive()) return false;
    kill(pid_, SIGTERM);
    const auto deadline = Clock::now() + std::chrono::milliseconds(timeout_ms);
    while (Clock::now() < deadline) {
      if (!alive()) return true;
      sleep_ms(20);
    }
    kill(pid_, SIGKILL);
    while (alive()) sleep_ms(10);
    return false;
  }
  size_t err_count(const std::string& needle) {
    pump();
    std::lock_guard<std::mutex> l(mu_);
    size_t n = 0;
    for (size_t at = stderr_.find(needle); at != std::string::npos; at = stderr_.find(needle, at + 1)) ++n;
    return n;
  }
  std::string err_tail(size_t bytes) {
    pump();
    std::lock_guard<std::mutex> l(mu_);
    return stderr_.size() > bytes ? stderr_.substr(stderr_.size() - bytes) : stderr_;
  }

 private:
  void pump() {
    std::lock_guard<std::mutex> l(mu_);
    char buf[65536];
    ssize_t n;
    while ((n = read(out_, buf, sizeof buf)) > 0) stdout_.append(buf, size_t(n));
    while ((n = read(err_, buf, sizeof buf)) > 0) {
      stderr_.append(buf, size_t(n));
      if (stderr_.size() > (8u << 20)) stderr_.erase(0, stderr_.size() - (4u << 20));  // keep the tail
    }
  }
  std::string name_, command_;
  pid_t pid_ = -1;
  int out_ = -1, err_ = -1;
  std::mutex mu_;
  std::string stdout_, stderr_;
  std::optional<int> status_;
  std::optional<Clock::time_point> died_at_;
};

std::string json_field(const std::string& line, const std::string& key) {
  auto at = line.find("\"" + key + "\": \"");
  if (at == std::string::npos) return {};
  at += key.size() + 5;
  return line.substr(at, line.find('"', at) - at);
}
uint16_t port_of(const std::string& url) {
  auto colon = url.rfind(':');
  if (colon == std::string::npos) return 0;
  return uint16_t(std::atoi(url.c_str() + colon + 1));
}

struct ProcSample {
  double rss_mb = 0;
  int threads = 0;
  bool ok = false;
};
ProcSample read_proc(pid_t pid) {
  ProcSample s;
  std::ifstream f("/proc/" + std::to_string(pid) + "/status");
  std::string line;
  while (std::getline(f, line)) {
    if (line.rfind("VmRSS:", 0) == 0) {
      s.rss_mb = std::atof(line.c_str() + 6) / 1024.0;
      s.ok = true;
    } else if (line.rfind("Threads:", 0) == 0) {
      s.threads = std::atoi(line.c_str() + 8);
    }
  }
  return s;
}

std::string read_first_line(const char* path) {
  std::ifstream f(path);
  std::string line;
  std::getline(f, line);
  return line;
}

// ---------------------------------------------------------------------------------------
// Counters shared by the client threads and the sampler.

struct Counters {
  std::atomic<uint64_t> wb_frames{0};          // frames received by the well-behaved clients (churn)
  std::atomic<uint64_t> sessions_served{0};    // well-behaved sessions that got all their frames
  std::atomic<uint64_t> sessions_started{0};
  std::atomic<uint64_t> sessions_aborted{0};   // ended by dropping TCP (a crashed client), on purpose
  std::atomic<uint64_t> wb_refused{0};         // connects refused (e.g. HTTP 503)
  std::atomic<uint64_t> wb_failures{0};        // sessions that ended early: error reply, close, stall
  std::atomic<uint64_t> malformed_sent{0};
  std::atomic<uint64_t> malformed_answered{0};  // an error reply came back (or, for a fatal kind, the close)
  std::atomic<uint64_t> malformed_error_replies{0};
  std::atomic<uint64_t> malformed_connections{0};
  std::atomic<uint64_t> reader_connections{0};
  std::atomic<uint64_t> reader_requests{0};
  std::atomic<uint64_t> reader_bytes_sent{0};
  // Streaming time of the well-behaved sessions (first to last frame) and frames in it.
  std::mutex mu;
  double stream_s = 0;
  uint64_t stream_frames = 0;
  std::vector<std::string> wb_errors;  // the first few, for the summary
  void wb_error(const std::string& e) {
    ++wb_failures;
    std::lock_guard<std::mutex> l(mu);
    if (wb_errors.size() < 8) wb_errors.push_back(e);
  }
};

struct ClientSetup {
  std::string host = "127.0.0.1";
  uint16_t port = 0;
  int width = 320, height = 180;
  int frames_per_session = 30;
  std::vector<std::vector<uint8_t>> upload;  // the scene, packed
  const CameraLoop* loop = nullptr;
};

// One well-behaved session: connect, handshake, upload, `frames` frames along the camera loop
// (two requests outstanding), then close (or drop the TCP connection when `crash`). Stops early
// when *stop is set. stream_seconds > 0: stream for that long instead of a frame count.
struct SessionResult {
  bool connected = false, completed = false;
  uint64_t frames = 0;
  double stream_s = 0;  // first to last frame
  std::string error;
};
SessionResult run_session(const ClientSetup& cs, size_t loop_start, bool crash, const std::atomic<bool>* stop,
                          std::atomic<uint64_t>* frame_counter, double stream_seconds = 0) {
  SessionResult r;
  WsClient ws;
  std::string err;
  if (!ws.connect(cs.host, cs.port, "/ws", &err)) {
    r.error = "connect: " + err;
    return r;
  }
  r.connected = true;
  protocol::Handshake hs;
  hs.display = protocol::DisplayKind::jpeg;
  hs.jpeg_quality = 85;
  hs.width = cs.width;
  hs.height = cs.height;
  ws.send(protocol::encode(ClientRecord{hs}));
  protocol::Limits lim;
  auto deadline = Clock::now() + std::chrono::seconds(30);
  bool replied = false;
  while (!replied) {
    auto msg = ws.receive(200);
    if (!msg) {
      if (ws.closed()) { r.error = "closed before the handshake reply"; return r; }
      if (Clock::now() > deadline) { r.error = "no handshake reply in 30 s"; return r; }
      if (stop && *stop) return r;
      continue;
    }
    auto recs = protocol::decode_server(msg->data(), msg->size(), lim);
    if (!recs) { r.error = "undecodable server message: " + recs.error().message; return r; }
    for (auto& rec : recs.value()) {
      if (std::get_if<protocol::HandshakeReply>(&rec)) replied = true;
      if (auto* e = std::get_if<protocol::ErrorReply>(&rec)) { r.error = "server error: " + e->message; return r; }
    }
  }
  for (auto& m : cs.upload)
    if (!ws.send(m)) { r.error = "upload failed"; return r; }
  const size_t nloop = cs.loop->frames.size();
  uint32_t sent = 0;
  auto request = [&] {
    const size_t k = (loop_start + sent) % nloop;
    ws.send(protocol::encode(std::vector<ClientRecord>{protocol::SetCamera{cs.loop->camera(k)},
                                                        protocol::RenderRequest{sent}}));
    ++sent;
  };
  const uint64_t want = stream_seconds > 0 ? std::numeric_limits<uint64_t>::max() : uint64_t(cs.frames_per_session);
  request();
  request();
  Clock::time_point first{}, last = Clock::now();
  while (r.frames < want) {
    if (stop && *stop) break;
    auto msg = ws.receive(200);
    if (!msg) {
      if (ws.closed()) { r.error = "closed by the node after " + std::to_string(r.frames) + " frames"; break; }
      if (Clock::now() - last > std::chrono::seconds(30)) {
        r.error = "no frame for 30 s after " + std::to_string(r.frames) + " frames";
        break;
      }
      continue;
    }
    auto recs = protocol::decode_server(msg->data(), msg->size(), lim);
    if (!recs) { r.error = "undecodable server message: " + recs.error().message; break; }
    bool failed = false;
    for (auto& rec : recs.value()) {
      if (auto* e = std::get_if<protocol::ErrorReply>(&rec)) {
        r.error = "server error: " + e->message;
        failed = true;
      }
      if (!std::get_if<protocol::Frame>(&rec)) continue;
      const auto now = Clock::now();
      if (r.frames == 0) first = now;
      last = now;
      ++r.frames;
      if (frame_counter) ++*frame_counter;
      if (stream_seconds > 0 && std::chrono::duration<double>(now - first).count() >= stream_seconds) {
        r.completed = true;
        r.stream_s = std::chrono::duration<double>(last - first).count();
        ws.close();
        return r;
      }
      if (sent < want) request();
    }
    if (failed) break;
  }
  if (r.frames > 1) r.stream_s = std::chrono::duration<double>(last - first).count();
  r.completed = r.error.empty() && r.frames >= want;
  if (crash)
    ws.abort();
  else
    ws.close();
  return r;
}

// ---------------------------------------------------------------------------------------
// A tiny valid scene (one triangle, a camera) for the malformed client and the never-reader,
// so that their render requests render something.

std::vector<ClientRecord> tiny_scene() {
  Buffer b;
  b.type = Buffer::Type::f32;
  b.components = 3;
  b.f = {-1, -1, -5, 1, -1, -5, 0, 1, -5};
  Mesh mesh;
  mesh.positions = 1;
  Camera cam;
  return {protocol::SetBuffer{1, b, false}, protocol::SetMesh{1, mesh}, protocol::SetCamera{cam}};
}

void put_u32(std::vector<uint8_t>& m, size_t at, uint32_t v) {
  for (int i = 0; i < 4; ++i) m[at + size_t(i)] = uint8_t(v >> (8 * i));
}

// The malformed messages, by kind. `aborts_today` marks the kinds that abort the node inside
// Embree before issue 16's validation (excluded by --malformed safe).
struct Malformed {
  std::string kind;
  std::vector<uint8_t> bytes;
  bool text = false;          // sent as a WebSocket text message
  bool renders = false;       // carries a render request: a frame may come back
  bool aborts_today = false;
  bool fatal = false;         // the session is expected to end (fatal error code)
};

std::vector<Malformed> malformed_kinds() {
  using namespace protocol;
  std::vector<Malformed> v;
  const auto settings = encode(ClientRecord{Settings{0, 4}});
  {  // a valid message cut short
    auto m = settings;
    m.resize(m.size() - 3);
    v.push_back({"truncated", m});
  }
  v.push_back({"truncated_header", {'T', 'S', protocol::kVersion, 0, 1}});
  v.push_back({"empty", {}});
  {
    auto m = settings;
    m[0] = 'X';
    m[1] = 'X';
    v.push_back({"bad_magic", m});
  }
  {
    auto m = settings;
    m[3] = 1;
    v.push_back({"bad_channel", m});
  }
  {
    auto m = settings;
    put_u32(m, 4, 0xffffffffu);
    v.push_back({"huge_record_count", m});
  }
  {
    auto m = settings;
    put_u32(m, 12, 0xfffffff0u);
    v.push_back({"huge_body_length", m});
  }
  {
    auto m = settings;
    m[8] = 0x7f;
    v.push_back({"unknown_record", m});
  }
  {
    auto m = settings;
    m[10] = 1;
    v.push_back({"bad_reserved", m});
  }
  {
    Light l;
    l.type = Light::Type(9);
    v.push_back({"bad_enum_light", encode(ClientRecord{SetLight{1, l}})});
  }
  v.push_back({"bad_enum_remove", encode(ClientRecord{Remove{RecordType(0x55), 3}})});
  v.push_back({"huge_resolution", encode(ClientRecord{Resolution{100000, 100000}})});
  v.push_back({"huge_ao", encode(ClientRecord{Settings{100000, 100000}})});
  {
    Buffer b;
    b.components = 1;
    b.f = {1, 2, 3, 4};
    auto m = encode(ClientRecord{SetBuffer{7, b, false}});
    put_u32(m, 8 + 8 + 8, 0x3ffffffcu);  // value_count: 4 GiB declared, 16 bytes sent
    v.push_back({"huge_buffer_declared", m});
  }
  {
    Texture t;
    t.width = t.height = 2;
    t.rgba.assign(16, 255);
    SetTexture st;
    st.id = 3;
    st.texture = t;
    auto m = encode(ClientRecord{st});
    put_u32(m, 16 + 12, 100000);  // width
    put_u32(m, 16 + 16, 100000);  // height
    v.push_back({"huge_texture_declared", m});
  }
  {
    // Deflate bombs: 32 MiB of zeros deflate to about 32 KiB. Declared as 4 values, the stream
    // yields far more (bad_payload); declared honestly it is within the limits and accepted,
    // so the node inflates 32 MiB (the same id each time: it replaces itself).
    Buffer b;
    b.components = 1;
    b.f.assign(8u << 20, 0.0f);
    auto m = encode(ClientRecord{SetBuffer{9, b, true}});
    v.push_back({"deflate_bomb_32MiB", m});
    put_u32(m, 8 + 8 + 8, 4);
    v.push_back({"deflate_bomb_mismatch", m});
    put_u32(m, 8 + 8 + 8, 0xfffffff0u);
    v.push_back({"deflate_bomb_huge_declared", m});
    // A zlib stream cut in the middle.
    auto cut = encode(ClientRecord{SetBuffer{9, b, true}});
    const size_t keep = cut.size() / 2;
    cut.resize(keep);
    put_u32(cut, 12, uint32_t(keep - 16));  // body length matches what is there
    put_u32(cut, 8 + 8 + 8, uint32_t(8u << 20));
    v.push_back({"deflate_truncated", cut});
  }
  {
    Camera c;
    c.to_world.m[0] = std::numeric_limits<float>::quiet_NaN();
    v.push_back({"nan_camera", encode(std::vector<ClientRecord>{SetCamera{c}, RenderRequest{1}}), false, true});
    Camera z;
    z.to_world.m = {};
    v.push_back({"singular_camera", encode(std::vector<ClientRecord>{SetCamera{z}, RenderRequest{2}}), false, true});
    Camera huge;
    huge.to_world = Mat4::scale({1e19f, 1e19f, 1e19f});
    v.push_back({"huge_camera_1e19", encode(std::vector<ClientRecord>{SetCamera{huge}, RenderRequest{3}}), false, true,
                 true});
    Camera e38;
    e38.to_world.m[5] = 3e38f;
    v.push_back({"camera_element_3e38", encode(std::vector<ClientRecord>{SetCamera{e38}, RenderRequest{4}}), false,
                 true, true});
  }
  {
    auto mesh_with = [](const Mat4& t) {
      Mesh mesh;
      mesh.positions = 1;
      mesh.transform = t;
      return mesh;
    };
    Mat4 zero;
    zero.m = {};
    v.push_back({"mesh_zero_transform", encode(std::vector<ClientRecord>{SetMesh{1, mesh_with(zero)}, RenderRequest{5}}),
                 false, true, true});
    v.push_back({"mesh_zero_z_scale",
                 encode(std::vector<ClientRecord>{SetMesh{1, mesh_with(Mat4::scale({1, 1, 0}))}, RenderRequest{6}}),
                 false, true, true});
    v.push_back({"mesh_scale_1e-30",
                 encode(std::vector<ClientRecord>{SetMesh{1, mesh_with(Mat4::scale({1e-30f, 1e-30f, 1e-30f}))},
                                                  RenderRequest{7}}),
                 false, true, true});
  }
  {
    std::mt19937 rng(20261121);
    std::vector<uint8_t> g(4096);
    for (auto& b : g) b = uint8_t(rng());
    v.push_back({"garbage", g});
    auto g2 = g;  // garbage behind a valid header
    g2[0] = 'T', g2[1] = 'S', g2[2] = 1, g2[3] = 0;
    put_u32(g2, 4, 3);
    v.push_back({"garbage_after_header", g2});
  }
  v.push_back({"text_message", {'h', 'e', 'l', 'l', 'o'}, true});
  {
    auto m = settings;
    m[2] = 9;  // protocol version: fatal
    Malformed x{"bad_version", m};
    x.fatal = true;
    v.push_back(x);
  }
  {
    Malformed x{"second_handshake", encode(ClientRecord{Handshake{}})};
    x.fatal = true;
    v.push_back(x);
  }
  return v;
}

struct KindCount {
  uint64_t sent = 0, error_reply = 0, closed = 0, frame = 0, silent = 0;
};

// Sends malformed messages until *stop, each after a valid handshake and a tiny scene; a
// message is "answered" when an error reply comes back within 500 ms (or the node closes the
// session after a fatal one). Reconnects whenever the session ends.
void malformed_client(const ClientSetup& cs, const std::vector<Malformed>& kinds, const std::atomic<bool>& stop,
                      Counters& c, std::map<std::string, KindCount>& per_kind, std::mutex& per_kind_mu) {
  protocol::Limits lim;
  size_t next = 0;
  while (!stop) {
    WsClient ws;
    std::string err;
    if (!ws.connect(cs.host, cs.port, "/ws", &err, 2000)) {
      sleep_ms(100);
      continue;
    }
    ++c.malformed_connections;
    protocol::Handshake hs;
    hs.width = 64;
    hs.height = 36;
    ws.send(protocol::encode(ClientRecord{hs}));
    ws.send(protocol::encode(tiny_scene()));
    while (!stop && !ws.closed()) {
      const Malformed& m = kinds[next++ % kinds.size()];
      bool ok = m.text ? ws.send_text(std::string(m.bytes.begin(), m.bytes.end())) : ws.send(m.bytes);
      if (!ok) break;
      ++c.malformed_sent;
      KindCount k;
      k.sent = 1;
      const auto deadline = Clock::now() + std::chrono::milliseconds(500);
      bool answered = false, framed = false;
      while (Clock::now() < deadline && !(answered && (framed || !m.renders))) {
        auto msg = ws.receive(50);
        if (!msg) {
          if (ws.closed()) {  // an answer only where the kind is fatal (else the node dropped us, or died)
            k.closed = 1;
            answered = answered || m.fatal;
            break;
          }
          continue;
        }
        auto recs = protocol::decode_server(msg->data(), msg->size(), lim);
        if (!recs) continue;
        for (auto& r : recs.value()) {
          if (std::get_if<protocol::ErrorReply>(&r)) {
            ++c.malformed_error_replies;
            k.error_reply = 1;
            answered = true;
          }
          if (std::get_if<protocol::Frame>(&r)) framed = true;
        }
      }
      if (framed) k.frame = 1;
      if (answered) ++c.malformed_answered;
      if (!answered) k.silent = 1;
      {
        std::lock_guard<std::mutex> l(per_kind_mu);
        auto& t = per_kind[m.kind];
        t.sent += k.sent, t.error_reply += k.error_reply, t.closed += k.closed, t.frame += k.frame, t.silent += k.silent;
      }
      if (m.fatal) {  // the node ends the session: wait for the close, so the next kind starts afresh
        const auto close_deadline = Clock::now() + std::chrono::seconds(2);
        while (!ws.closed() && Clock::now() < close_deadline) ws.receive(50);
        break;
      }
    }
    ws.abort();
  }
}

// ---------------------------------------------------------------------------------------
// The never-reader: a raw TCP socket, a WebSocket upgrade written by hand, a handshake (S3TC,
// the biggest frames), a tiny scene, then a render request every 20 ms; it never reads, and
// its receive buffer is small, so whatever the node sends piles up on the node's side.

void ws_frame(std::vector<uint8_t>& out, const std::vector<uint8_t>& payload, uint32_t mask_seed) {
  const uint8_t mask[4] = {uint8_t(mask_seed), uint8_t(mask_seed >> 8), uint8_t(mask_seed >> 16), uint8_t(mask_seed >> 24)};
  const std::vector<uint8_t> f = masked_ws_frame(payload, mask);
  out.insert(out.end(), f.begin(), f.end());
}

// Sends all of `bytes` (blocking, bounded by deadline). False when the connection is gone.
bool send_all(int fd, const std::vector<uint8_t>& bytes, Clock::time_point deadline) {
  size_t at = 0;
  while (at < bytes.size()) {
    ssize_t n = ::send(fd, bytes.data() + at, bytes.size() - at, MSG_NOSIGNAL | MSG_DONTWAIT);
    if (n > 0) {
      at += size_t(n);
      continue;
    }
    if (n < 0 && (errno == EAGAIN || errno == EWOULDBLOCK)) {
      if (Clock::now() > deadline) return false;
      sleep_ms(5);
      continue;
    }
    return false;
  }
  return true;
}

void never_reader(const ClientSetup& cs, int width, int height, const std::atomic<bool>& stop, Counters& c) {
  uint32_t seed = 0x1234567u;
  while (!stop) {
    int fd = socket(AF_INET, SOCK_STREAM, 0);
    if (fd < 0) return;
    int small = 4096;
    setsockopt(fd, SOL_SOCKET, SO_RCVBUF, &small, sizeof small);
    sockaddr_in a{};
    a.sin_family = AF_INET;
    a.sin_port = htons(cs.port);
    inet_pton(AF_INET, cs.host.c_str(), &a.sin_addr);
    if (connect(fd, reinterpret_cast<sockaddr*>(&a), sizeof a) != 0) {
      close(fd);
      sleep_ms(200);
      continue;
    }
    ++c.reader_connections;
    std::string up = "GET /ws HTTP/1.1\r\nHost: " + cs.host + ":" + std::to_string(cs.port) +
                     "\r\nUpgrade: websocket\r\nConnection: Upgrade\r\nSec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\n"
                     "Sec-WebSocket-Version: 13\r\n\r\n";
    std::vector<uint8_t> out(up.begin(), up.end());
    protocol::Handshake hs;
    hs.display = protocol::DisplayKind::s3tc;
    hs.width = width;
    hs.height = height;
    ws_frame(out, protocol::encode(ClientRecord{hs}), seed++);
    ws_frame(out, protocol::encode(tiny_scene()), seed++);
    bool ok = send_all(fd, out, Clock::now() + std::chrono::seconds(5));
    uint32_t frame = 0;
    while (ok && !stop) {
      std::vector<uint8_t> req;
      ws_frame(req, protocol::encode(ClientRecord{protocol::RenderRequest{frame++}}), seed++);
      // A request that does not fit in the socket now is dropped (the node stopped reading us);
      // a closed connection ends this one.
      ssize_t n = ::send(fd, req.data(), req.size(), MSG_NOSIGNAL | MSG_DONTWAIT);
      if (n < 0 && errno != EAGAIN && errno != EWOULDBLOCK) break;
      if (n > 0 && size_t(n) < req.size())  // never leave half a frame behind
        ok = send_all(fd, std::vector<uint8_t>(req.begin() + n, req.end()), Clock::now() + std::chrono::seconds(5));
      if (n > 0) {
        ++c.reader_requests;
        c.reader_bytes_sent += uint64_t(req.size());
      }
      sleep_ms(20);
    }
    close(fd);
  }
}

// ---------------------------------------------------------------------------------------

struct ProcStats {
  double baseline_mb = 0, peak_mb = 0, after_drain_mb = 0, final_mb = 0;
  int baseline_threads = 0, peak_threads = 0, after_drain_threads = 0, final_threads = 0;
  double drain_return_s = -1, final_return_s = -1;  // seconds until within tolerance; -1: never
  double trimmed_mb = -1;  // --trim-probe: RSS after malloc_trim(0) in the node (-1: not probed)
};

const char* kHelp =
    "tessera soak [--topology single|cluster] [--seconds S] [--clients N] [--scene S.gltf --camera-loop L.json]\n"
    "             [--size W H] [--frames-per-session F] [--alone-seconds A] [--drain-seconds D]\n"
    "             [--rss-tolerance-mb M] [--rss-tolerance-pct P] [--thread-tolerance T] [--threads T]\n"
    "             [--malformed all|safe] [--reader-size W H] [--binary PATH] [--trim-probe] [--full-drain] [--samples FILE]\n"
    "Robustness soak: starts the nodes (a single node, or a dedicated master with two workers) as\n"
    "child processes, measures one client alone, then churns N clients (default 8) for S seconds\n"
    "(default 60): N-2 well-behaved (connect, upload the scene, render F frames, disconnect, repeat),\n"
    "one sending malformed messages, one never reading. Samples each node's RSS and threads every\n"
    "second (JSON lines, to FILE with --samples FILE), then a summary line. Fails (exit 1) when a\n"
    "node died, or when a process's RSS did not come back to within max(M MiB, P% of baseline) of its baseline (defaults 64 MiB,\n"
    "25%) or its threads to within T (default 2) after the churn, in D seconds (default 20).\n"
    "--malformed safe leaves out the kinds that abort a node without issue 16's validation.\n"
    "--full-drain: the drain and final phases last --drain-seconds each, back or not (to watch trends).\n"
    "--trim-probe: at the end, gdb calls malloc_trim(0) in each node and the RSS after it is reported\n"
    "(trimmed_rss_mb: what the allocator kept but was free; needs gdb and ptrace rights; not a verdict;\n"
    "it runs after the verdict's measurements, and gdb may disturb the node's clean exit).\n"
    "Defaults: pavilion scene and camera loop, 320x180 JPEG, never-reader 640x360 S3TC.\n";

int run(const std::vector<std::string>& argv_in) {
  std::vector<std::string> argv = argv_in;
  auto has = [&](const char* o) { return std::find(argv.begin(), argv.end(), o) != argv.end(); };
  if (has("--help")) {
    std::fputs(kHelp, stdout);
    return 0;
  }
  if (!has("--scene")) argv.insert(argv.end(), {"--scene", "../shared/scenes/pavilion/scene.gltf"});
  if (!has("--camera-loop")) argv.insert(argv.end(), {"--camera-loop", "../shared/scenes/pavilion/camera-loop.json"});
  Args args(argv);
  const std::string topology = args.str("--topology", "single");
  const double seconds = args.number("--seconds", 60);
  const int clients = int(args.integer("--clients", 8));
  const int frames_per_session = int(args.integer("--frames-per-session", 30));
  const double alone_seconds = args.number("--alone-seconds", 5);
  const double drain_seconds = args.number("--drain-seconds", 20);
  const double tol_mb = args.number("--rss-tolerance-mb", 64);
  const double tol_pct = args.number("--rss-tolerance-pct", 25);
  const int tol_threads = int(args.integer("--thread-tolerance", 2));
  const long threads = args.integer("--threads", 0);
  const std::string malformed_mode = args.str("--malformed", "all");
  const int reader_w = int(args.integer("--reader-size", 640, 0)), reader_h = int(args.integer("--reader-size", 360, 1));
  std::string binary = args.str("--binary", "");
  const bool trim_probe = args.flag("--trim-probe");
  const bool full_drain = args.flag("--full-drain");
  const std::string samples_path = args.str("--samples", "");
  SceneSetup setup = load_scene(args, 320, 180, LoopOption::required);
  args.finish();
  if (topology != "single" && topology != "cluster") throw std::invalid_argument("--topology must be single or cluster");
  if (clients < 3 || clients > 15) throw std::invalid_argument("--clients must be 3..15 (one malformed, one never-reader)");
  if (!(seconds >= 1) || !(alone_seconds >= 1) || !(drain_seconds >= 1) || frames_per_session < 1)
    throw std::invalid_argument("--seconds, --alone-seconds, --drain-seconds >= 1, --frames-per-session >= 1");
  if (malformed_mode != "all" && malformed_mode != "safe") throw std::invalid_argument("--malformed must be all or safe");
  if (binary.empty()) {
    char buf[4096];
    ssize_t n = readlink("/proc/self/exe", buf, sizeof buf - 1);
    if (n <= 0) throw std::runtime_error("cannot find this executable (/proc/self/exe); give --binary");
    binary.assign(buf, size_t(n));
  }
  // The per-second samples: stdout, or a file (under ctest, so that the verdict at the end of
  // the output is not lost among a hundred sample lines).
  FILE* samples = stdout;
  std::unique_ptr<FILE, int (*)(FILE*)> samples_file(nullptr, &std::fclose);
  if (!samples_path.empty()) {
    samples_file.reset(std::fopen(samples_path.c_str(), "w"));
    if (!samples_file) throw std::runtime_error("cannot write --samples " + samples_path);
    samples = samples_file.get();
  }
  const int W = setup.loaded.scene.width(), H = setup.loaded.scene.height();
  const std::string load_start = read_first_line("/proc/loadavg");
  const auto t0 = Clock::now();

  // --- The nodes.
  const std::string th = std::to_string(threads > 0 ? threads : 0);
  auto common = [&](std::vector<std::string> a) {
    if (threads > 0) a.insert(a.end(), {"--threads", th});
    return a;
  };
  std::vector<std::unique_ptr<NodeProcess>> nodes;
  uint16_t http_port = 0;
  auto start_failed = [&](const std::string& why) {
    std::fprintf(stderr, "soak: %s\n", why.c_str());
    for (auto& n : nodes) std::fprintf(stderr, "--- %s stderr tail:\n%s\n", n->name().c_str(), n->err_tail(3000).c_str());
    std::printf("{\"summary\": true, \"topology\": \"%s\", \"started\": false, \"error\": %s}\n", topology.c_str(),
                json_str(why).c_str());
    return 2;
  };
  if (topology == "single") {
    nodes.push_back(std::make_unique<NodeProcess>(
        "node", binary, common({"--port", "0", "--web-root", "web", "--tessera.name=node"})));
    auto line = nodes[0]->first_line(60000);
    if (!line) return start_failed("the node did not start");
    http_port = port_of(json_field(*line, "listening"));
  } else {
    std::string children;
    for (const char* w : {"w1", "w2"}) {
      nodes.push_back(std::make_unique<NodeProcess>(
          w, binary, common({"--no-http", "--cluster-port", "0", std::string("--tessera.name=") + w})));
      auto line = nodes.back()->first_line(60000);
      if (!line) return start_failed(std::string("worker ") + w + " did not start");
      children += (children.empty() ? "" : ",") + json_field(*line, "cluster");
    }
    nodes.insert(nodes.begin(),
                 std::make_unique<NodeProcess>("master", binary,
                                               common({"--port", "0", "--web-root", "web", "--no-render", "--children",
                                                       children, "--tessera.name=master"})));
    auto line = nodes[0]->first_line(60000);
    if (!line) return start_failed("the master did not start");
    http_port = port_of(json_field(*line, "listening"));
    const auto deadline = Clock::now() + std::chrono::seconds(30);
    while (nodes[0]->err_count("\"child_connected\"") < 2 && Clock::now() < deadline) sleep_ms(50);
    if (nodes[0]->err_count("\"child_connected\"") < 2) return start_failed("the master did not connect both workers");
  }
  if (http_port == 0) return start_failed("no port in the node's first line");
  for (auto& n : nodes) std::fprintf(stderr, "soak: %s pid %d: %s\n", n->name().c_str(), int(n->pid()), n->command().c_str());

  ClientSetup cs;
  cs.port = http_port;
  cs.width = W;
  cs.height = H;
  cs.frames_per_session = frames_per_session;
  cs.loop = &setup.loop;
  {
    protocol::SceneRecordOptions o;
    o.resolution = false;  // the handshake chose it
    const auto records = protocol::scene_to_records(setup.loaded.scene, o);
    cs.upload = protocol::pack_messages(records, 8u << 20);
  }
  size_t upload_bytes = 0;
  for (auto& m : cs.upload) upload_bytes += m.size();

  // --- Sampling: one JSON line a second, peaks per process, deaths noticed.
  Counters c;
  std::vector<ProcStats> ps(nodes.size());
  std::vector<ProcSample> last(nodes.size());
  std::mutex sample_mu;
  std::string phase = "warmup";
  std::atomic<bool> sampling{true};
  std::vector<uint64_t> churn_frames_per_s;  // well-behaved frames in each churn second
  bool any_died = false;
  auto sample_once = [&](bool print) {
    std::lock_guard<std::mutex> l(sample_mu);
    std::string procs;
    for (size_t i = 0; i < nodes.size(); ++i) {
      const bool alive = nodes[i]->alive();
      ProcSample s = alive ? read_proc(nodes[i]->pid()) : ProcSample{};
      if (!alive) any_died = true;
      if (s.ok) {
        last[i] = s;
        ps[i].peak_mb = std::max(ps[i].peak_mb, s.rss_mb);
        ps[i].peak_threads = std::max(ps[i].peak_threads, s.threads);
      }
      procs += format("%s{\"name\": \"%s\", \"pid\": %d, \"alive\": %s, \"rss_mb\": %.1f, \"threads\": %d}", i ? ", " : "",
                   nodes[i]->name().c_str(), int(nodes[i]->pid()), alive ? "true" : "false", s.rss_mb, s.threads);
    }
    if (print)
      std::fprintf(samples, "{\"t\": %.1f, \"phase\": \"%s\", \"wb_frames\": %llu, \"sessions_served\": %llu, "
                  "\"malformed_sent\": %llu, \"malformed_answered\": %llu, \"reader_requests\": %llu, \"procs\": [%s]}\n",
                  since(t0), phase.c_str(), (unsigned long long)c.wb_frames, (unsigned long long)c.sessions_served,
                  (unsigned long long)c.malformed_sent, (unsigned long long)c.malformed_answered,
                  (unsigned long long)c.reader_requests, procs.c_str());
    std::fflush(samples);
  };
  auto set_phase = [&](const std::string& p) {
    std::lock_guard<std::mutex> l(sample_mu);
    phase = p;
  };
  std::thread sampler([&] {
    uint64_t prev_frames = 0;
    while (sampling) {
      sample_once(true);
      {
        std::lock_guard<std::mutex> l(sample_mu);
        const uint64_t f = c.wb_frames;
        if (phase == "churn") churn_frames_per_s.push_back(f - prev_frames);
        prev_frames = f;
      }
      for (int k = 0; k < 10 && sampling; ++k) sleep_ms(100);
    }
  });
  struct SamplerGuard {
    std::atomic<bool>& on;
    std::thread& t;
    ~SamplerGuard() {
      on = false;
      if (t.joinable()) t.join();
    }
  } sampler_guard{sampling, sampler};

  // --- Warm-up: one ordinary session, then one client alone, streaming.
  std::atomic<bool> no_stop{false};
  auto warm = run_session(cs, 0, false, &no_stop, nullptr);
  if (!warm.completed) return start_failed("the warm-up session failed: " + warm.error);
  set_phase("alone");
  auto alone = run_session(cs, 0, false, &no_stop, nullptr, alone_seconds);
  if (!alone.completed) return start_failed("the alone session failed: " + alone.error);
  const double alone_fps = alone.stream_s > 0 ? double(alone.frames - 1) / alone.stream_s : 0;
  std::fprintf(stderr, "soak: alone %.2f fps (%llu frames in %.1f s)\n", alone_fps, (unsigned long long)alone.frames,
               alone.stream_s);

  // --- Baseline: once the node has let the warm-up sessions go (settled a few seconds).
  set_phase("settle");
  sleep_ms(3000);
  sample_once(false);
  {
    std::lock_guard<std::mutex> l(sample_mu);
    for (size_t i = 0; i < nodes.size(); ++i) {
      ps[i].baseline_mb = last[i].rss_mb;
      ps[i].baseline_threads = last[i].threads;
    }
  }
  auto tolerance = [&](size_t i) { return std::max(tol_mb, ps[i].baseline_mb * tol_pct / 100.0); };

  // --- Churn.
  const auto kinds_all = malformed_kinds();
  std::vector<Malformed> kinds;
  for (auto& k : kinds_all)
    if (malformed_mode == "all" || !k.aborts_today) kinds.push_back(k);
  std::map<std::string, KindCount> per_kind;
  std::mutex per_kind_mu;
  std::atomic<bool> stop_churn{false}, stop_reader{false};
  set_phase("churn");
  const auto churn0 = Clock::now();
  std::vector<std::thread> ts;
  const int well_behaved = clients - 2;
  for (int ci = 0; ci < well_behaved; ++ci)
    ts.emplace_back([&, ci] {
      std::mt19937 rng(uint32_t(1000 + ci));
      uint64_t n = 0;
      while (!stop_churn) {
        ++c.sessions_started;
        const bool crash = (n++ % 4) == 3;  // every fourth session drops its TCP connection instead of closing
        auto r = run_session(cs, rng() % setup.loop.frames.size(), crash, &stop_churn, &c.wb_frames);
        {
          std::lock_guard<std::mutex> l(c.mu);
          if (r.frames > 1) {
            c.stream_s += r.stream_s;
            c.stream_frames += r.frames - 1;
          }
        }
        if (r.completed) {
          ++c.sessions_served;
          if (crash) ++c.sessions_aborted;
        } else if (!stop_churn) {
          if (!r.connected) ++c.wb_refused;
          c.wb_error("client " + std::to_string(ci) + ": " + r.error);
          sleep_ms(200);
        }
      }
    });
  ts.emplace_back([&] { malformed_client(cs, kinds, stop_churn, c, per_kind, per_kind_mu); });
  std::thread reader([&] { never_reader(cs, reader_w, reader_h, stop_reader, c); });
  // The churn ends early when the node the clients talk to has died: nobody can be served.
  while (since(churn0) < seconds && nodes[0]->alive()) sleep_ms(50);
  const bool churn_cut = since(churn0) < seconds;
  const double churn_s = since(churn0);
  const uint64_t churn_frames = c.wb_frames;
  stop_churn = true;
  for (auto& t : ts) t.join();

  // --- Drain (the never-reader still connected), then final (it has gone).
  auto wait_back = [&](double ProcStats::*return_s, double ProcStats::*mb, int ProcStats::*thr) {
    const auto d0 = Clock::now();
    while (true) {
      sleep_ms(500);
      sample_once(false);
      bool all_back = true;
      {
        std::lock_guard<std::mutex> l(sample_mu);
        for (size_t i = 0; i < nodes.size(); ++i) {
          if (!nodes[i]->alive()) continue;  // a dead node is a failure of its own, nothing to wait for
          const bool back = last[i].rss_mb <= ps[i].baseline_mb + tolerance(i) &&
                            last[i].threads <= ps[i].baseline_threads + tol_threads;
          if (back && ps[i].*return_s < 0) ps[i].*return_s = since(d0);
          if (!back) ps[i].*return_s = -1;
          all_back = all_back && back;
        }
      }
      if (all_back && since(d0) >= 2.0 && !full_drain) break;  // back, and stays back for a moment
      if (since(d0) >= drain_seconds) break;
    }
    std::lock_guard<std::mutex> l(sample_mu);
    for (size_t i = 0; i < nodes.size(); ++i) {
      ps[i].*mb = last[i].rss_mb;
      ps[i].*thr = last[i].threads;
    }
  };
  set_phase("drain");
  wait_back(&ProcStats::drain_return_s, &ProcStats::after_drain_mb, &ProcStats::after_drain_threads);
  set_phase("final");
  stop_reader = true;
  reader.join();
  wait_back(&ProcStats::final_return_s, &ProcStats::final_mb, &ProcStats::final_threads);
  sample_once(true);
  sampling = false;
  sampler.join();
  // --trim-probe: how much of what a node still holds is free memory its allocator keeps
  // (glibc's arenas) rather than memory still in use: gdb calls malloc_trim(0) inside it.
  if (trim_probe)
    for (size_t i = 0; i < nodes.size(); ++i) {
      if (!nodes[i]->alive()) continue;
      const std::string cmd = "timeout 60 gdb -p " + std::to_string(nodes[i]->pid()) +
                              " -batch -ex 'call (int)malloc_trim(0)' >/dev/null 2>&1";
      // gdb's exit status is not a guide (on this kernel it reports failing to restore the
      // AVX-512 state and exits 171 after the call has run): the RSS before and after is.
      const int rc = std::system(cmd.c_str());
      sleep_ms(200);
      if (rc == 127 * 256) {
        std::fprintf(stderr, "soak: --trim-probe: no gdb\n");
        break;
      }
      if (auto s = read_proc(nodes[i]->pid()); s.ok) ps[i].trimmed_mb = s.rss_mb;
    }

  // --- Verdict and summary.
  std::vector<std::string> failures;
  std::string procs;
  for (size_t i = 0; i < nodes.size(); ++i) {
    const bool alive = nodes[i]->alive();
    const std::string ended = nodes[i]->how_it_ended();
    std::string last_words;  // a dead node's last stderr line (the assertion, if Embree aborted)
    if (!alive) {
      std::istringstream tail(nodes[i]->err_tail(4000));
      for (std::string line; std::getline(tail, line);)
        if (!line.empty()) last_words = line.substr(0, 400);
      auto at = nodes[i]->died_at();
      failures.push_back(nodes[i]->name() + " died (" + ended + ")" +
                         (at ? format(" %.1f s into the run", std::chrono::duration<double>(*at - t0).count()) : ""));
      std::fprintf(stderr, "--- %s died (%s); stderr tail:\n%s\n", nodes[i]->name().c_str(), ended.c_str(),
                   nodes[i]->err_tail(2000).c_str());
    } else {
      if (ps[i].after_drain_mb > ps[i].baseline_mb + tolerance(i))
        failures.push_back(format("%s RSS %.1f MiB after the drain (never-reader connected), baseline %.1f + %.1f",
                               nodes[i]->name().c_str(), ps[i].after_drain_mb, ps[i].baseline_mb, tolerance(i)));
      if (ps[i].final_mb > ps[i].baseline_mb + tolerance(i))
        failures.push_back(format("%s RSS %.1f MiB at the end, baseline %.1f + %.1f", nodes[i]->name().c_str(),
                               ps[i].final_mb, ps[i].baseline_mb, tolerance(i)));
      if (ps[i].final_threads > ps[i].baseline_threads + tol_threads)
        failures.push_back(format("%s has %d threads at the end, baseline %d + %d", nodes[i]->name().c_str(),
                               ps[i].final_threads, ps[i].baseline_threads, tol_threads));
    }
    procs += format("%s{\"name\": \"%s\", \"alive\": %s, \"ended\": %s, \"last_words\": %s, \"baseline_rss_mb\": %.1f, \"peak_rss_mb\": %.1f, "
                 "\"after_drain_rss_mb\": %.1f, \"final_rss_mb\": %.1f, \"trimmed_rss_mb\": %.1f, \"tolerance_mb\": %.1f, "
                 "\"drain_return_s\": %.1f, \"final_return_s\": %.1f, \"baseline_threads\": %d, \"peak_threads\": %d, "
                 "\"after_drain_threads\": %d, \"final_threads\": %d}",
                 i ? ", " : "", nodes[i]->name().c_str(), alive ? "true" : "false", json_str(ended).c_str(),
                 json_str(last_words).c_str(), ps[i].baseline_mb, ps[i].peak_mb, ps[i].after_drain_mb, ps[i].final_mb, ps[i].trimmed_mb, tolerance(i),
                 ps[i].drain_return_s, ps[i].final_return_s, ps[i].baseline_threads, ps[i].peak_threads,
                 ps[i].after_drain_threads, ps[i].final_threads);
  }
  if (churn_frames == 0) failures.push_back("the well-behaved clients received no frame during the churn");
  // Shut the nodes down (a clean exit is reported, not required).
  std::string shutdown;
  for (auto& n : nodes) {
    const bool was_alive = n->alive();
    const bool clean = was_alive && n->stop(10000);
    shutdown += format("%s\"%s\": %s", shutdown.empty() ? "" : ", ", n->name().c_str(),
                    json_str(!was_alive ? "dead" : clean ? n->how_it_ended() : "killed after 10 s").c_str());
  }
  std::string kinds_json;
  for (auto& [name, k] : per_kind)
    kinds_json += format("%s\"%s\": {\"sent\": %llu, \"error_reply\": %llu, \"closed\": %llu, \"frame\": %llu, "
                      "\"silent\": %llu}",
                      kinds_json.empty() ? "" : ", ", name.c_str(), (unsigned long long)k.sent,
                      (unsigned long long)k.error_reply, (unsigned long long)k.closed, (unsigned long long)k.frame,
                      (unsigned long long)k.silent);
  std::vector<double> per_s(churn_frames_per_s.begin(), churn_frames_per_s.end());
  size_t stalled = 0;
  for (auto f : churn_frames_per_s) stalled += f == 0;
  double stream_fps = 0;
  {
    std::lock_guard<std::mutex> l(c.mu);
    stream_fps = c.stream_s > 0 ? double(c.stream_frames) / c.stream_s : 0;
  }
  std::string errs, fails;
  for (auto& e : c.wb_errors) errs += (errs.empty() ? "" : ", ") + json_str(e);
  for (auto& f : failures) fails += (fails.empty() ? "" : ", ") + json_str(f);
  struct utsname un{};
  uname(&un);
  const double fps_total = churn_s > 0 ? double(churn_frames) / churn_s : 0;
  std::printf(
      "{\"summary\": true, \"topology\": \"%s\", \"started\": true, \"seconds\": %.1f, \"churn_cut_short\": %s, \"clients\": %d, "
      "\"well_behaved\": %d, \"malformed_mode\": \"%s\", \"malformed_kinds\": %zu, "
      "\"sessions_started\": %llu, \"sessions_served\": %llu, \"sessions_dropped_tcp\": %llu, \"wb_refused\": %llu, "
      "\"wb_failures\": %llu, \"wb_errors\": [%s], \"wb_frames_churn\": %llu, "
      "\"alone_fps\": %.2f, \"alone_frames\": %llu, \"wb_fps_total_churn\": %.2f, \"wb_fps_per_client_churn\": %.2f, "
      "\"wb_stream_fps_per_session_churn\": %.2f, \"wb_frames_per_s_median\": %.1f, \"wb_frames_per_s_min\": %.0f, "
      "\"stalled_seconds\": %zu, "
      "\"malformed_sent\": %llu, \"malformed_answered\": %llu, \"malformed_error_replies\": %llu, "
      "\"malformed_connections\": %llu, \"malformed_by_kind\": {%s}, "
      "\"reader_connections\": %llu, \"reader_requests\": %llu, \"reader_bytes_sent\": %llu, "
      "\"procs\": [%s], \"shutdown\": {%s}, \"rss_tolerance\": \"max(%.0f MiB, %.0f%% of baseline)\", "
      "\"thread_tolerance\": %d, \"drain_seconds\": %.0f, "
      "\"scene\": %s, \"upload_bytes\": %zu, \"triangles\": %zu, \"width\": %d, \"height\": %d, "
      "\"frames_per_session\": %d, \"reader_size\": \"%dx%d s3tc\", \"render_threads\": %s, "
      "\"cpu\": %s, \"isa\": %s, \"hardware_threads\": %d, \"kernel\": %s, \"load_start\": %s, \"load_end\": %s, "
      "\"wall_s\": %.1f, \"failures\": [%s], \"ok\": %s}\n",
      topology.c_str(), churn_s, churn_cut ? "true" : "false", clients, well_behaved, malformed_mode.c_str(), kinds.size(),
      (unsigned long long)c.sessions_started, (unsigned long long)c.sessions_served,
      (unsigned long long)c.sessions_aborted, (unsigned long long)c.wb_refused, (unsigned long long)c.wb_failures,
      errs.c_str(), (unsigned long long)churn_frames, alone_fps, (unsigned long long)alone.frames, fps_total,
      fps_total / well_behaved, stream_fps, median(per_s), per_s.empty() ? 0.0 : *std::min_element(per_s.begin(), per_s.end()),
      stalled, (unsigned long long)c.malformed_sent, (unsigned long long)c.malformed_answered,
      (unsigned long long)c.malformed_error_replies, (unsigned long long)c.malformed_connections, kinds_json.c_str(),
      (unsigned long long)c.reader_connections, (unsigned long long)c.reader_requests,
      (unsigned long long)c.reader_bytes_sent, procs.c_str(), shutdown.c_str(), tol_mb, tol_pct, tol_threads,
      drain_seconds, json_str(setup.scene_path).c_str(), upload_bytes, setup.loaded.scene.triangle_count(), W, H,
      frames_per_session, reader_w, reader_h, threads > 0 ? std::to_string(threads).c_str() : "\"all\"",
      json_str(cpu_model()).c_str(), json_str(isa_name(detect_packet_layout())).c_str(), hardware_threads(),
      json_str(std::string(un.release)).c_str(), json_str(load_start).c_str(),
      json_str(read_first_line("/proc/loadavg")).c_str(), since(t0), fails.c_str(), failures.empty() ? "true" : "false");
  std::fflush(stdout);
  for (auto& f : failures) std::fprintf(stderr, "soak: FAIL %s\n", f.c_str());
  if (failures.empty()) std::fprintf(stderr, "soak: ok\n");
  (void)any_died;
  return failures.empty() ? 0 : 1;
}

const Command reg("soak", "robustness soak: churning, malformed and never-reading clients against real nodes", run);

}  // namespace
}  // namespace tessera::app
