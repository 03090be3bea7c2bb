// tessera loadtest --scene S.gltf --camera-loop L.json [--clients N] [--display jpeg|s3tc|mjpeg|h264]
//                  [--seconds S | --frames F] [--warmup K] [--size W H] [--ao A] [--quality Q] [--host H --port P [--token T]] [--threads T]
//                  [--tls [--tls-ca F] | --tls-cert C --tls-key K] [--outstanding 1|2] [--latency-seconds L]
//                  [--on-streaming CMD] [--request-hz R]
// Uploads the scene from N simultaneous WebSocket clients; each replays the camera loop with two
// render requests outstanding (or one: --outstanding 1). Once every client has received K frames (all connected and
// streaming), a common window of S seconds opens; the frames each client receives inside it
// are counted. Prints one JSON line per frame received in the window and a summary (frames
// per second per client and in total over the common window, pipeline/encode/bytes medians).
// Without --port it runs a node in this process on a free localhost port.
#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <mutex>
#include <thread>

#include <caf/all.hpp>

#include "app/command.h"
#include "app/common.h"
#include "app/node_config.h"
#include "protocol/scene_records.h"
#include "net/http.h"
#include "net/server.h"
#include "net/ws_client.h"

namespace tessera::app {
namespace {

using Clock = std::chrono::steady_clock;

struct FrameRecord {
  int client = 0;
  uint32_t frame = 0;
  protocol::FrameTimings t;
  size_t bytes = 0;
  double received_ms = 0;  // since the common window opened
  double latency_ms = 0;   // from sending the frame's camera and request to receiving the frame
};

int run(const std::vector<std::string>& argv) {
  Args args(argv);
  if (args.flag("--help")) {
    std::puts("tessera loadtest --scene S.gltf --camera-loop L.json [--clients N] [--display jpeg|s3tc|mjpeg|h264]\n"
              "                 [--seconds S | --frames F] [--warmup K] [--size W H] [--ao A] [--quality Q]\n"
              "                 [--host H --port P [--token T]] [--threads T]\n"
              "                 [--tls [--tls-ca F] | --tls-cert C --tls-key K] [--outstanding 1|2] [--latency-seconds L]\n"
              "                 [--on-streaming CMD] [--request-hz R]\n"
              "Frames per second over a common window of S seconds (default 20) that opens once every client\n"
              "has received K frames (default 2). --frames F: the window closes instead once every client has\n"
              "received F frames after its K warm-up frames (frame numbers K..K+F-1, the camera loop's frames\n"
              "of those indices), so runs on different trees render the same frames. mjpeg: frames counted from the WebSocket's Frame records\n"
              "(timings, empty payload); the JPEGs go to /mjpeg/NAME, which each client also reads (not with --tls):\n"
              "the summary's mjpeg_stream has the parts shown, their bytes and their latency (from the request of\n"
              "the frame a part's X-Tessera-Frame names to the part's end). --token: the access\n"
              "token for a node that asks for one (tessera token; sent as ?access_token=). --tls: wss:// to the node at\n"
              "--port (its certificate verified against --tls-ca F when given). --tls-cert/--tls-key: the in-process\n"
              "node serves WSS with them, and the clients connect over TLS. latency_ms: from sending a frame's camera\n"
              "and render request to receiving the frame. --outstanding: render requests each client keeps in flight\n"
              "(default 2: the node renders a frame while the one before is encoded and sent, and latency includes\n"
              "the wait behind it; 1: the next camera is sent when a frame arrives, so latency is one round trip,\n"
              "the rendering, encoding and transfer of one frame, and nothing else). --latency-seconds L: after the\n"
              "window, each client lets its requests in flight arrive, then keeps one outstanding for L seconds; the\n"
              "summary's \"one_outstanding\" has that phase's latency (the scene is uploaded once for both).\n"
              "--on-streaming CMD: once every client has its first frame (the scene is uploaded), the clients wait\n"
              "while CMD runs (sh -c), then go on; with --warmup 2 or more, so no counted frame was asked for\n"
              "before it. A bench shapes its link there (bench/display_network.sh). --request-hz R: each client sends\n"
              "the next camera and render request every 1/R s whatever arrives, as a browser does during a drag\n"
              "(a late tick sends one request, not a burst); the node renders the newest and merges the others\n"
              "(the summary's node_dropped), and latency_ms is from a frame's own request to the frame.");
    return 0;
  }
  int threads = 0;
  auto limit = limit_threads(args, &threads);
  SceneSetup setup = load_scene(args, 1280, 720, LoopOption::required);
  const int clients = int(args.integer("--clients", 1));
  const std::string display = args.str("--display", "jpeg");
  const double seconds = double(args.integer("--seconds", 20));
  const int warmup = int(args.integer("--warmup", 2));
  const int frames_wanted = int(args.integer("--frames", 0));
  const long outstanding_arg = args.integer("--outstanding", -1);  // -1: not given
  const int outstanding = outstanding_arg < 0 ? 2 : int(outstanding_arg);
  const double latency_seconds = args.number("--latency-seconds", 0);
  const std::string on_streaming = args.str("--on-streaming");
  const double request_hz = args.number("--request-hz", 0);
  const int ao = int(args.integer("--ao", 0));
  const int quality = int(args.integer("--quality", 85));
  std::string host = args.str("--host", "127.0.0.1");
  long port = args.integer("--port", -1);
  const std::string token = args.str("--token");
  bool tls = args.flag("--tls");
  const std::string tls_ca = args.str("--tls-ca"), tls_cert = args.str("--tls-cert"), tls_key = args.str("--tls-key");
  args.finish();
  if (tls_cert.empty() != tls_key.empty()) throw std::invalid_argument("--tls-cert and --tls-key go together");
  if (!tls_cert.empty() && port >= 0) throw std::invalid_argument("--tls-cert/--tls-key are for the in-process node (no --port)");
  if (!tls_cert.empty()) tls = true;
  if (clients < 1 || clients > 64 || seconds < 1 || warmup < 1 || frames_wanted < 0)
    throw std::invalid_argument("--clients 1..64, --seconds >= 1, --warmup >= 1, --frames >= 0");
  if (outstanding_arg != -1 && (outstanding_arg < 1 || outstanding_arg > 2)) throw std::invalid_argument("--outstanding must be 1 or 2");
  if (!(latency_seconds >= 0 && latency_seconds <= 3600)) throw std::invalid_argument("--latency-seconds must be 0..3600");
  if (!(request_hz >= 0 && request_hz <= 1000)) throw std::invalid_argument("--request-hz must be 0..1000");
  if (request_hz > 0 && (latency_seconds > 0 || outstanding_arg != -1))
    throw std::invalid_argument("--request-hz sends requests on a clock: not with --outstanding or --latency-seconds");
  if (!on_streaming.empty() && warmup < 2) throw std::invalid_argument("--on-streaming needs --warmup 2 or more");
  if (display != "jpeg" && display != "s3tc" && display != "mjpeg" && display != "h264")
    throw std::invalid_argument("--display must be jpeg, s3tc, mjpeg or h264");
  const int W = setup.loaded.scene.width(), H = setup.loaded.scene.height();

  // An in-process node unless --port names one.
  std::unique_ptr<NodeConfig> cfg;
  std::unique_ptr<caf::actor_system> sys;
  std::unique_ptr<Server> server;
  if (port < 0) {
    cfg = std::make_unique<NodeConfig>();
    cfg->log_frames = false;
    cfg->port = 0;
    auto settings = cfg->node_settings();
    settings->log = [](const Event&) {};
    ServerOptions o = cfg->server_options();
    o.max_clients = size_t(clients);
    o.tls_cert = tls_cert;
    o.tls_key = tls_key;
    sys = std::make_unique<caf::actor_system>(*cfg);
    server = std::make_unique<Server>(*sys, settings, o);
    server->start();
    port = server->port();
  }

  const auto records = protocol::scene_to_records(setup.loaded.scene, {false, false, false, true});
  const auto upload = protocol::pack_messages(records, 16u << 20);
  std::mutex mu;
  using Received = std::vector<std::pair<Clock::time_point, FrameRecord>>;
  std::vector<Received> received(static_cast<size_t>(clients));
  std::vector<double> upload_ms(size_t(clients), 0);
  std::vector<protocol::Stats> last_stats(static_cast<size_t>(clients));  // the node's own figures
  std::vector<std::string> errors;
  std::vector<std::string> tls_sessions(static_cast<size_t>(clients));
  std::atomic<int> ready{0}, finished{0}, complete{0};  // complete: clients with their --frames
  std::atomic<bool> stop{false};
  // The latency phase (--latency-seconds): opened by the main thread when the window closes;
  // each client's frames of it (latency, rendering ms), and the clients that have finished it.
  std::atomic<bool> phase_one{false};
  // --on-streaming: clients with their first frame, and the command's end.
  std::atomic<int> streaming{0};
  std::atomic<bool> go{on_streaming.empty()};
  std::atomic<int> phase_one_done{0};
  std::vector<std::vector<std::pair<double, double>>> one_outstanding(static_cast<size_t>(clients));
  // MJPEG without TLS: each client also reads its session's stream (/mjpeg/loadtestN) as a
  // browser's <img> would, and the parts (arrival, frame number, bytes) are what it was shown.
  struct Part {
    Clock::time_point at;
    long frame;
    size_t bytes;
  };
  const bool read_stream = display == "mjpeg" && !tls;
  std::vector<std::vector<Part>> parts(static_cast<size_t>(clients));
  std::vector<std::vector<Clock::time_point>> sent_times(static_cast<size_t>(clients));  // by frame number
  std::vector<uint32_t> phase_one_firsts(static_cast<size_t>(clients), UINT32_MAX);
  auto client_main = [&](int ci) {
    WsClient ws;
    if (tls) ws.use_tls(tls_ca);
    std::string err;
    bool counted_ready = false;
    auto& sent_at = sent_times[size_t(ci)];  // by frame number
    std::thread reader;
    auto fail = [&](const std::string& e) {
      std::lock_guard<std::mutex> l(mu);
      errors.push_back("client " + std::to_string(ci) + ": " + e);
    };
    auto body = [&] {
      std::string resource = display == "mjpeg" ? "/ws?session=loadtest" + std::to_string(ci) : "/ws";
      if (!token.empty()) resource += (display == "mjpeg" ? "&access_token=" : "?access_token=") + token;
      if (!ws.connect(host, uint16_t(port), resource, &err)) return fail(err);
      tls_sessions[size_t(ci)] = ws.tls_session();
      protocol::Handshake hs;
      hs.display = display == "s3tc"    ? protocol::DisplayKind::s3tc
                   : display == "mjpeg" ? protocol::DisplayKind::mjpeg
                   : display == "h264"  ? protocol::DisplayKind::h264
                                        : protocol::DisplayKind::jpeg;
      hs.jpeg_quality = uint8_t(quality);
      hs.width = W;
      hs.height = H;
      auto t_up = Clock::now();
      ws.send(protocol::encode(protocol::ClientRecord{hs}));
      for (auto& m : upload) ws.send(m);
      ws.send(protocol::encode(protocol::ClientRecord{protocol::Settings{uint32_t(ao), 4}}));
      uint32_t sent = 0, arrived = 0;
      int got = 0;
      uint32_t phase_one_first = UINT32_MAX;  // the first frame requested in the latency phase
      Clock::time_point phase_one_start;
      bool phase_one_over = false;
      auto request = [&] {
        size_t k = size_t(sent) % setup.loop.frames.size();
        sent_at.push_back(Clock::now());
        ws.send(protocol::encode(std::vector<protocol::ClientRecord>{protocol::SetCamera{setup.loop.camera(k)},
                                                                     protocol::RenderRequest{sent}}));
        ++sent;
      };
      request();
      if (outstanding > 1 && request_hz == 0) request();  // two: the node renders f+1 while f is encoded and sent
      // --request-hz: the next request's time (a late tick sends one, then keeps the period).
      const auto period = std::chrono::duration_cast<Clock::duration>(
          std::chrono::duration<double>(request_hz > 0 ? 1.0 / request_hz : 1.0));
      auto next_request = Clock::now() + period;
      auto tick = [&] {
        const auto now = Clock::now();
        if (request_hz == 0 || now < next_request || !go) return;
        request();
        next_request = std::max(next_request + period, now);
      };
      // The latency phase's first request, once every frame in flight has arrived (also when
      // that happened before the phase opened).
      auto open_phase_one = [&](Clock::time_point now) {
        if (phase_one && phase_one_first == UINT32_MAX && arrived == sent) {
          phase_one_first = sent;
          phase_one_firsts[size_t(ci)] = sent;
          phase_one_start = now;
          request();
        }
      };
      protocol::Limits lim;
      auto last = Clock::now();
      while (!stop) {
        int wait_ms = phase_one ? 20 : 200;
        if (request_hz > 0)
          wait_ms = int(std::clamp<int64_t>(
              std::chrono::duration_cast<std::chrono::milliseconds>(next_request - Clock::now()).count() + 1, 1, 200));
        auto msg = ws.receive(wait_ms);
        tick();
        if (!msg) {
          open_phase_one(Clock::now());
          if (ws.closed()) return fail("connection closed after " + std::to_string(got) + " frames");
          if (!phase_one_over && Clock::now() - last > std::chrono::seconds(120))
            return fail("no frame for 120 s after " + std::to_string(got) + " frames");
          continue;
        }
        const auto now = Clock::now();
        auto recs = protocol::decode_server(msg->data(), msg->size(), lim);
        if (!recs) return fail("undecodable server message: " + recs.error().message);
        for (auto& r : recs.value()) {
          if (auto* e = std::get_if<protocol::ErrorReply>(&r)) return fail("server error: " + e->message);
          if (auto* st = std::get_if<protocol::Stats>(&r)) last_stats[size_t(ci)] = *st;
          auto* f = std::get_if<protocol::Frame>(&r);
          if (!f) continue;
          last = now;
          ++arrived;
          if (read_stream && !reader.joinable()) {  // the session (and so its stream) exists now
            const std::string target =
                "/mjpeg/loadtest" + std::to_string(ci) + (token.empty() ? "" : "?access_token=" + token);
            reader = std::thread([&, ci, target] {
              std::string e;
              auto& mine = parts[size_t(ci)];
              const bool ok = http::read_mjpeg_stream(
                  host, uint16_t(port), target,
                  [&](std::vector<uint8_t>&& p, long frame) {
                    mine.push_back(Part{Clock::now(), frame, p.size()});
                    return true;
                  },
                  [&] { return bool(stop); }, &e);
              if (!ok) fail("MJPEG stream: " + e);
            });
          }
          if (phase_one) {  // the latency phase: one request at a time, once those in flight are in
            if (phase_one_over) continue;
            if (f->frame >= phase_one_first && f->frame < sent_at.size()) {
              one_outstanding[size_t(ci)].push_back(
                  {std::chrono::duration<double, std::milli>(now - sent_at[f->frame]).count(), f->timings.rendering_ms});
              if (now - phase_one_start >= std::chrono::duration<double>(latency_seconds)) {
                phase_one_over = true;
                ++phase_one_done;
                continue;
              }
            }
            if (phase_one_first == UINT32_MAX) open_phase_one(now);
            else if (arrived == sent) request();
            continue;
          }
          if (frames_wanted > 0 && got >= warmup + frames_wanted) continue;  // requested ahead: not counted
          if (got == 0) upload_ms[size_t(ci)] = std::chrono::duration<double, std::milli>(now - t_up).count();
          const double latency =
              f->frame < sent_at.size() ? std::chrono::duration<double, std::milli>(now - sent_at[f->frame]).count() : 0;
          received[size_t(ci)].push_back({now, FrameRecord{ci, f->frame, f->timings, msg->size(), 0, latency}});
          if (++got == warmup && !counted_ready) {
            counted_ready = true;
            ++ready;
          }
          if (got == 1 && !go) {
            ++streaming;
            while (!go && !stop) std::this_thread::sleep_for(std::chrono::milliseconds(2));
          }
          if (frames_wanted > 0 && got == warmup + frames_wanted) {
            ++complete;
            continue;
          }
          if (request_hz == 0) request();
        }
      }
    };
    body();
    ++finished;
    ws.close();
    if (reader.joinable()) reader.join();
  };
  std::vector<std::thread> ts;
  for (int c = 0; c < clients; ++c) ts.emplace_back(client_main, c);
  // The common window: opens when every client streams, lasts --seconds.
  if (!on_streaming.empty()) {
    while (streaming < clients && finished == 0) std::this_thread::sleep_for(std::chrono::milliseconds(5));
    if (finished == 0) {
      const int rc = std::system(on_streaming.c_str());
      if (rc != 0) {
        std::lock_guard<std::mutex> l(mu);
        errors.push_back("--on-streaming command failed (status " + std::to_string(rc) + ")");
      }
    }
    go = true;
  }
  while (ready < clients && finished == 0) std::this_thread::sleep_for(std::chrono::milliseconds(10));
  const auto w0 = Clock::now();
  while (finished == 0 && (frames_wanted > 0 ? complete < clients : Clock::now() - w0 < std::chrono::duration<double>(seconds)))
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  const auto w1 = Clock::now();
  if (latency_seconds > 0) {
    phase_one = true;
    while (finished == 0 && phase_one_done < clients) std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  stop = true;
  for (auto& t : ts) t.join();
  if (server) server->stop();
  for (auto& e : errors) std::fprintf(stderr, "error: %s\n", e.c_str());
  const double window_s = std::chrono::duration<double>(w1 - w0).count();
  std::vector<double> fps(size_t(clients), 0);
  std::vector<FrameRecord> all;
  for (int c = 0; c < clients; ++c) {
    size_t n = 0, i = 0;
    for (auto& [t, f] : received[size_t(c)])
      // --frames: exactly the frames after the client's warm-up (the window may open a poll
      // period after the last warm-up frame); otherwise those inside the common window.
      if (frames_wanted > 0 ? i++ >= size_t(warmup) : (t >= w0 && t < w1)) {
        f.received_ms = std::chrono::duration<double, std::milli>(t - w0).count();
        all.push_back(f);
        ++n;
      }
    fps[size_t(c)] = window_s > 0 ? double(n) / window_s : 0;
  }
  std::vector<double> pipeline, encode, rendering, kernel, bytes, sat, tiling, latency;
  for (auto& f : all) {
    std::printf("{\"client\": %d, \"frame\": %u, \"kernel_ms\": %.3f, \"rendering_ms\": %.3f, \"sat_ms\": %.3f, "
                "\"tiling_ms\": %.3f, \"encode_ms\": %.3f, \"pipeline_ms\": %.3f, \"bytes\": %zu, \"received_ms\": %.3f, "
                "\"latency_ms\": %.3f}\n",
                f.client, f.frame, f.t.kernel_ms, f.t.rendering_ms, f.t.sat_ms, f.t.tiling_ms, f.t.encode_ms,
                f.t.pipeline_ms, f.bytes, f.received_ms, f.latency_ms);
    latency.push_back(f.latency_ms);
    pipeline.push_back(f.t.pipeline_ms);
    encode.push_back(f.t.encode_ms);
    rendering.push_back(f.t.rendering_ms);
    kernel.push_back(f.t.kernel_ms);
    sat.push_back(f.t.sat_ms);
    tiling.push_back(f.t.tiling_ms);
    bytes.push_back(double(f.bytes));
  }
  // Bytes per frame as the node counts them (Stats): for MJPEG the JPEG parts, which the
  // WebSocket's Frame records do not carry.
  std::vector<double> node_bytes;
  uint64_t node_frames = 0, node_dropped = 0;
  for (auto& st : last_stats) {
    if (st.frames) node_bytes.push_back(double(st.bytes_sent) / st.frames);
    node_frames += st.frames;
    node_dropped += st.dropped;
  }
  std::string one_json = "null";
  if (latency_seconds > 0) {
    std::vector<double> lat, ren;
    for (auto& v : one_outstanding)
      for (auto& [l, r] : v) lat.push_back(l), ren.push_back(r);
    char b[256];
    std::snprintf(b, sizeof b,
                  "{\"frames\": %zu, \"median_latency_ms\": %.3f, \"p90_latency_ms\": %.3f, \"median_rendering_ms\": %.3f}",
                  lat.size(), median(lat), percentile(lat, 0.9), median(ren));
    one_json = b;
  }
  std::string stream_json = "null";
  if (read_stream) {
    std::vector<double> lat, one_lat, sizes;
    size_t in_window = 0;
    for (int c = 0; c < clients; ++c) {
      const auto& sent = sent_times[size_t(c)];
      for (const Part& p : parts[size_t(c)]) {
        if (p.frame < 0 || size_t(p.frame) >= sent.size()) continue;
        const double ms = std::chrono::duration<double, std::milli>(p.at - sent[size_t(p.frame)]).count();
        if (p.at >= w0 && p.at < w1) {
          ++in_window;
          lat.push_back(ms);
          sizes.push_back(double(p.bytes));
        } else if (p.at >= w1 && uint32_t(p.frame) >= phase_one_firsts[size_t(c)]) {
          one_lat.push_back(ms);
        }
      }
    }
    char b[512];
    std::snprintf(b, sizeof b,
                  "{\"parts_in_window\": %zu, \"fps\": %.3f, \"median_bytes\": %.0f, \"median_latency_ms\": %.3f, "
                  "\"p90_latency_ms\": %.3f, \"one_outstanding_parts\": %zu, \"one_outstanding_median_latency_ms\": %.3f, "
                  "\"one_outstanding_p90_latency_ms\": %.3f}",
                  in_window, window_s > 0 ? double(in_window) / window_s : 0.0, median(sizes), median(lat),
                  percentile(lat, 0.9), one_lat.size(), median(one_lat), percentile(one_lat, 0.9));
    stream_json = b;
  }
  double total_fps = 0;
  std::string per;
  for (size_t i = 0; i < fps.size(); ++i) {
    total_fps += fps[i];
    per += (i ? ", " : "") + std::to_string(fps[i]);
  }
  std::printf("{\"summary\": true, \"clients\": %d, \"display\": \"%s\", \"quality\": %d, \"width\": %d, \"height\": %d, "
              "\"ao\": %d, \"window_s\": %.3f, \"frames_in_window\": %zu, \"fps_per_client\": [%s], \"fps_total\": %.3f, "
              "\"median_rendering_ms\": %.3f, \"median_kernel_ms\": %.3f, \"median_sat_ms\": %.3f, "
              "\"median_tiling_ms\": %.3f, \"median_encode_ms\": %.3f, \"median_pipeline_ms\": %.3f, "
              "\"median_latency_ms\": %.3f, \"p90_latency_ms\": %.3f, "
              "\"median_bytes\": %.0f, \"node_bytes_per_frame\": %.0f, \"median_upload_ms\": %.1f, \"errors\": %zu, \"outstanding\": %d, \"request_hz\": %g, \"node_frames\": %llu, \"node_dropped\": %llu, \"one_outstanding\": %s, \"mjpeg_stream\": %s, \"scene\": %s, "
              "\"triangles\": %zu, \"node\": \"%s\", \"tls\": %s, \"cpu\": %s, \"threads\": %d}\n",
              clients, display.c_str(), quality, W, H, ao, window_s, all.size(), per.c_str(), total_fps, median(rendering),
              median(kernel), median(sat), median(tiling), median(encode), median(pipeline), median(latency),
              percentile(latency, 0.9), median(bytes), median(node_bytes), median(upload_ms), errors.size(), request_hz > 0 ? 0 : outstanding, request_hz, (unsigned long long)node_frames,
              (unsigned long long)node_dropped, one_json.c_str(), stream_json.c_str(),
              json_str(setup.scene_path).c_str(), setup.loaded.scene.triangle_count(), server ? "in-process" : "external",
              tls ? json_str(tls_sessions[0].empty() ? "yes" : tls_sessions[0]).c_str() : "false",
              json_str(cpu_model()).c_str(), threads);
  return errors.empty() ? 0 : 1;
}

const Command reg("loadtest", "N WebSocket clients against a node: fps, pipeline, encode and bytes per frame", run);

}  // namespace
}  // namespace tessera::app
