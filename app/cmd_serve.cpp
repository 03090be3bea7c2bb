// tessera serve [--config configs/single.ini] [--host H] [--port P] [--web-root DIR]
//               [--scene S.gltf] [--threads T] [--renderer client|raytracer|rasterizer] [--tessera.NAME=VALUE ...]
#include <csignal>
#include <cstdio>
#include <thread>

#include <caf/all.hpp>

#include "app/command.h"
#include "app/common.h"
#include "app/node_config.h"
#include "renderer/rasterizer.h"

namespace tessera::app {
namespace {

const char* kHelp =
    "tessera serve [--config FILE.ini] [--host H] [--port P] [--web-root DIR] [--scenes-root DIR]\n"
    "              [--scene S.gltf] [--threads T]   (DIR of --scenes-root is served at /scenes/)\n"
    "              [--renderer client|raytracer|rasterizer]\n"
    "              [--tessera.NAME=VALUE ...] [--scheduler.max-threads=N]\n"
    "Runs one node: the web client and demo pages over HTTP at http://H:P/, the client protocol on the\n"
    "WebSocket ws://H:P/ws, MJPEG streams at /mjpeg/<session token>. Defaults: 127.0.0.1:8080, web/.\n"
    "--scene preloads a glTF scene for clients that connect with an empty scene. Settings (INI group\n"
    "[tessera], see configs/single.ini): host, port, web-root, scene, max-clients, render-threads,\n"
    "logical-cores, single-core-perf, max-width, max-height, max-message-bytes, max-buffer-bytes,\n"
    "max-client-bytes, max-triangles, max-texture-size, log-frames. Stops on SIGINT/SIGTERM.\n"
    "--renderer: 'client' (default) renders each session with the renderer its handshake asks for (the\n"
    "ray tracer unless the page says renderer=\"rasterizer\"); raytracer or rasterizer renders every\n"
    "session with that one. The listening line says whether the rasterizer's GL context can be created.\n";

int run(const std::vector<std::string>& argv) {
  Args args(argv);
  if (args.flag("--help")) { std::fputs(kHelp, stdout); return 0; }
  std::string config = args.str("--config");
  std::string host = args.str("--host"), web_root = args.str("--web-root"), scene = args.str("--scene");
  std::string scenes_root = args.str("--scenes-root");
  long port = args.integer("--port", -1);
  long threads = args.integer("--threads", 0);
  std::string renderer = args.str("--renderer", "client");
  if (renderer != "client" && renderer != "raytracer" && renderer != "rasterizer")
    throw std::invalid_argument("--renderer must be client, raytracer or rasterizer, not '" + renderer + "'");
  // Everything else of the form --group.name=value goes to CAF's parser.
  caf::actor_system_config::string_list caf_args;
  for (const auto& a : argv)
    if (a.rfind("--", 0) == 0 && a.find('=') != std::string::npos && a.find('.') != std::string::npos) {
      caf_args.push_back(a);
      args.flag(a);
    }
  args.finish();

  // Block the stop signals before any thread starts, so sigwait below receives them.
  sigset_t sigs;
  sigemptyset(&sigs);
  sigaddset(&sigs, SIGINT);
  sigaddset(&sigs, SIGTERM);
  pthread_sigmask(SIG_BLOCK, &sigs, nullptr);

  NodeConfig cfg;
  if (auto err = cfg.parse(caf_args, config.empty() ? nullptr : config.c_str()))
    throw std::invalid_argument("configuration: " + cfg.render(err));
  if (!config.empty()) {
    std::FILE* f = std::fopen(config.c_str(), "r");
    if (!f) throw std::invalid_argument("cannot read config file " + config);
    std::fclose(f);
  }
  if (!host.empty()) cfg.host = host;
  if (port >= 0) cfg.port = int(port);
  if (!web_root.empty()) cfg.web_root = web_root;
  if (!scene.empty()) cfg.scene = scene;
  if (threads > 0) cfg.render_threads = int(threads);
  std::unique_ptr<tbb::global_control> limit;
  if (cfg.render_threads > 0)
    limit = std::make_unique<tbb::global_control>(tbb::global_control::max_allowed_parallelism, size_t(cfg.render_threads));
  auto settings = cfg.node_settings();
  if (renderer != "client")
    settings->renderer = int(renderer == "rasterizer" ? protocol::RendererKind::rasterizer : protocol::RendererKind::raytracer);
  // Probe the rasterizer once, so that the operator sees whether it can serve (a session that
  // asks for it on a node without EGL gets the same reason as an error, and others go on).
  std::string gl_why;
  bool gl_ok = rasterizer_available(&gl_why);
  if (renderer == "rasterizer" && !gl_ok) throw std::runtime_error("--renderer rasterizer: " + gl_why);
  ServerOptions opts = cfg.server_options();
  if (!scenes_root.empty()) opts.scenes_root = scenes_root;
  caf::actor_system sys{cfg};
  Server server(sys, settings, opts);
  server.start();
  std::printf("{\"listening\": \"http://%s:%u/\", \"websocket\": \"ws://%s:%u/ws\", \"web_root\": %s, "
              "\"scene\": %s, \"max_clients\": %d, \"render_threads\": %d, \"cpu\": %s, \"renderer\": %s, "
              "\"rasterizer\": %s}\n",
              opts.host.c_str(), server.port(), opts.host.c_str(), server.port(), json_str(opts.web_root).c_str(),
              json_str(cfg.scene).c_str(), cfg.max_clients,
              cfg.render_threads > 0 ? cfg.render_threads : hardware_threads(), json_str(cpu_model()).c_str(),
              json_str(renderer).c_str(), json_str(gl_ok ? "available" : "unavailable: " + gl_why).c_str());
  std::fflush(stdout);
  int sig = 0;
  sigwait(&sigs, &sig);
  std::fprintf(stderr, "{\"stopping\": true, \"signal\": %d}\n", sig);
  server.stop();
  sys.await_all_actors_done();
  return 0;
}

const Command reg("serve", "run a node: web client over HTTP, client protocol over WebSocket", run);

}  // namespace
}  // namespace tessera::app
