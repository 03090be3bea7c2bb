// tessera serve [--config configs/single.ini] [--host H] [--port P] [--web-root DIR]
//               [--scene S.gltf] [--threads T] [--renderer client|raytracer|rasterizer] [--tessera.NAME=VALUE ...]
#include <csignal>
#include <cstdio>
#include <cstdlib>
#ifdef __GLIBC__
#include <malloc.h>
#endif
#include <thread>

#include <caf/all.hpp>
#include <caf/io/all.hpp>
#include <caf/openssl/publish.hpp>

#include "app/command.h"
#include "app/common.h"
#include "app/node_config.h"
#include "net/http.h"
#include "renderer/embree_device.h"
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
    "max-client-bytes, max-triangles, max-texture-size, log-frames; resource bounds: handshake-timeout-ms,\n"
    "max-node-bytes (memory budget over all clients, 0: half the physical memory), max-mjpeg-per-session,\n"
    "max-mjpeg-viewers. Admission (docs/operations.md): token-key (key file of signed access tokens, see\n"
    "`tessera token`), token-file (static tokens, one per line), allowed-origins (default [\"self\",\n"
    "\"loopback\"]), require-origin, max-connections-per-ip. TLS: tls-cert and tls-key (PEM files) make the\n"
    "port HTTPS and WSS only (TLS 1.2+; scripts/tls-cert.sh makes a self-signed pair for local use); SIGHUP\n"
    "reads them again (a renewed certificate: new connections get it, open sessions go on; a bad pair is\n"
    "logged and the old one kept). With TLS: hsts-max-age (seconds of Strict-Transport-Security; default 0,\n"
    "off: it pins the host name on every port to https, so set it only for a public name, e.g. 31536000),\n"
    "http-redirect-port (plain HTTP there redirects GET/HEAD to https://, 308; default 0, off).\n"
    "Cluster (docs/operations.md): [--cluster-port P] publishes this node to parents; [--children H:P,H:P]\n"
    "names its children; [--no-render] makes it a hub or dedicated master; [--no-http] serves no clients.\n"
    "INI: cluster-port, cluster-host (default 127.0.0.1), children, render, http, name, task-timeout-ms,\n"
    "reconnect-ms, cluster-tls-cert, cluster-tls-key, cluster-tls-ca (mutual TLS between nodes, all three\n"
    "or none: scripts/cluster-certs.sh makes them),\n"
    "max-workers, keepalive-misses, reproject (default true: the balancer carries the last frame's cost\n"
    "into the new camera with the workers' per-packet depths; false: the paper's previous-frame map).\n"
    "--renderer: 'client' (default) renders each session with the renderer its handshake asks for (the\n"
    "ray tracer unless the page says renderer=\"rasterizer\"); raytracer or rasterizer renders every\n"
    "session with that one. The listening line says whether the rasterizer's GL context can be created.\n"
    "Stops on SIGINT/SIGTERM; SIGHUP reloads the TLS certificate.\n";

// What the node admits, for the listening line: which kinds of token it asks for (never a
// token, a key or a file's content), the page origins it takes and the per-address limit.
std::string admission_json(const ServerOptions& o) {
  const char* tokens = o.tokens.signed_tokens() && o.tokens.static_tokens() ? "signed+static"
                       : o.tokens.signed_tokens()                          ? "signed"
                       : o.tokens.static_tokens()                          ? "static"
                                                                           : "none";
  std::string origins;
  for (const std::string& e : o.origins.describe()) origins += (origins.empty() ? "" : ", ") + json_str(e);
  return std::string("{\"tokens\": ") + json_str(tokens) + ", \"allowed_origins\": [" + origins +
         "], \"require_origin\": " + (o.origins.require_origin() ? "true" : "false") +
         ", \"max_connections_per_ip\": " + std::to_string(o.max_connections_per_ip) + "}";
}

int run(const std::vector<std::string>& argv) {
  Args args(argv);
  if (args.flag("--help")) { std::fputs(kHelp, stdout); return 0; }
  std::string config = args.str("--config");
  std::string host = args.str("--host"), web_root = args.str("--web-root"), scene = args.str("--scene");
  std::string scenes_root = args.str("--scenes-root");
  long port = args.integer("--port", -1);
  long threads = args.integer("--threads", 0);
  long cluster_port = args.integer("--cluster-port", -2);
  std::string children = args.str("--children");
  bool no_render = args.flag("--no-render"), no_http = args.flag("--no-http");
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

  // A node's memory comes back after its sessions end only if glibc's arenas do not keep it
  // fragmented: with its default of 8 arenas per core, the soak (docs/results/soak.md) left a
  // master 76 MiB and workers 60 MiB above their baselines with a session still streaming;
  // with 2 arenas every process came back within 40 MiB and the peaks fell by a fifth.
  // MALLOC_ARENA_MAX in the environment still wins.
#ifdef __GLIBC__
  if (!std::getenv("MALLOC_ARENA_MAX")) mallopt(M_ARENA_MAX, 2);
#endif
  // Block the stop signals and SIGHUP (reload the TLS certificate) before any thread starts, so
  // that sigwait below receives them on this thread: no signal handler runs anywhere.
  sigset_t sigs;
  sigemptyset(&sigs);
  sigaddset(&sigs, SIGINT);
  sigaddset(&sigs, SIGTERM);
  sigaddset(&sigs, SIGHUP);
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
  if (cluster_port >= -1) cfg.cluster_port = int(cluster_port);
  if (!children.empty()) {
    cfg.children.clear();
    for (size_t at = 0; at <= children.size();) {
      size_t comma = children.find(',', at);
      if (comma == std::string::npos) comma = children.size();
      if (comma > at) cfg.children.push_back(children.substr(at, comma - at));
      at = comma + 1;
    }
  }
  if (no_render) cfg.renders = false;
  if (no_http) cfg.http = false;
  // CAF's middleman for a cluster node, over its OpenSSL module with the node's certificates
  // (checked now: a bad file is a start-up error, not a crash on CAF's network thread later).
  const std::vector<std::string> cluster_warnings = cfg.load_cluster_modules();
  std::unique_ptr<tbb::global_control> limit;
  if (cfg.render_threads > 0)
    limit = std::make_unique<tbb::global_control>(tbb::global_control::max_allowed_parallelism, size_t(cfg.render_threads));
  auto settings = cfg.node_settings();
  // The ray tracers' Embree device lives as long as the node, and with it the BVHs that sessions
  // share (renderer/geometry_cache.h): a later visitor of a scene finds its meshes built.
  EmbreeDevice::set_geometry_cache_limit(uint64_t(cfg.geometry_cache_mb) << 20);
  EmbreeDevice::set_high_quality_bvh(cfg.bvh_quality == "high");
  std::shared_ptr<EmbreeDevice> embree;
  if (cfg.renders) embree = EmbreeDevice::acquire();
  if (renderer != "client")
    settings->renderer = int(renderer == "rasterizer" ? protocol::RendererKind::rasterizer : protocol::RendererKind::raytracer);
  // Probe the rasterizer once, so that the operator sees whether it can serve (a session that
  // asks for it on a node without EGL gets the same reason as an error, and others go on).
  std::string gl_why;
  bool gl_ok = rasterizer_available(&gl_why);
  if (renderer == "rasterizer" && !gl_ok) throw std::runtime_error("--renderer rasterizer: " + gl_why);
  ServerOptions opts = cfg.server_options();
  if (!scenes_root.empty()) opts.scenes_root = scenes_root;
  // References: files of this node's /scenes/, and URLs of the listed origins over HTTP(S).
  AssetOptions assets;
  assets.scenes_root = opts.scenes_root;
  assets.origins = cfg.asset_origins;
  assets.cache_bytes = uint64_t(cfg.asset_cache_mb) << 20;
  assets.max_file_bytes = uint64_t(cfg.asset_max_file_mb) << 20;
  try {
    settings->assets = std::make_shared<AssetStore>(assets, [](const std::string& url, uint64_t max_bytes,
                                                               std::vector<uint8_t>& body, std::string& error) {
      return http::fetch_url(url, max_bytes, body, error);
    });
  } catch (const std::runtime_error& e) {
    throw std::invalid_argument(e.what());
  }
  caf::actor_system sys{cfg};
  // Every actor's events go through one logger (actors/event.h); this is its only strong handle.
  logger_actor logger = spawn_logger(sys, settings->log);
  settings->logger = caf::actor_cast<caf::weak_actor_ptr>(logger);
  node_actor node;
  int published = -1;
  std::unique_ptr<Server> server;
  try {
    if (cfg.cluster()) {
      node = spawn_node(sys, settings);
      settings->node = caf::actor_cast<caf::weak_actor_ptr>(node);
      if (cfg.cluster_port >= 0) {
        // With TLS only CAF's OpenSSL module listens: every connection starts with the TLS
        // handshake, and a peer without a certificate of the cluster CA gets nothing of CAF's.
        const uint16_t at = uint16_t(cfg.cluster_port);
        auto p = cfg.cluster_tls() ? caf::openssl::publish(node, at, cfg.cluster_host.c_str(), true)
                                   : sys.middleman().publish(node, at, cfg.cluster_host.c_str(), true);
        if (!p)
          throw std::invalid_argument("cannot publish the node on " + cfg.cluster_host + ":" +
                                      std::to_string(cfg.cluster_port) + ": " + sys.render(p.error()));
        published = *p;
      }
      node_log(*settings, cluster_security_event(cfg, settings->name, published, cluster_warnings));
    }
    if (cfg.http) {
      server = std::make_unique<Server>(sys, settings, opts);
      server->start();
    }
  } catch (...) {
    // The node actor ticks forever: without its exit the actor system's destructor waits for
    // it, and with the stop signals blocked the process would hang (on a port in use, say).
    if (node) caf::anon_send_exit(node, caf::exit_reason::user_shutdown);
    throw;
  }
  std::string kids;
  for (auto& c : cfg.children) kids += (kids.empty() ? "" : ", ") + json_str(c);
  std::printf("{\"listening\": %s, \"websocket\": %s, \"cluster\": %s, \"name\": %s, \"children\": [%s], "
              "\"render\": %s, \"web_root\": %s, \"scene\": %s, \"max_clients\": %d, \"render_threads\": %d, "
              "\"cpu\": %s, \"renderer\": %s, \"rasterizer\": %s, \"bvh_quality\": %s, \"max_node_bytes\": %llu, "
              "\"handshake_timeout_ms\": %u, \"admission\": %s, \"http_redirect\": %s, \"hsts_max_age\": %u}\n",
              server ? json_str(std::string(opts.tls() ? "https" : "http") + "://" + opts.host + ":" +
                                std::to_string(server->port()) + "/").c_str()
                     : "null",
              server ? json_str(std::string(opts.tls() ? "wss" : "ws") + "://" + opts.host + ":" +
                                std::to_string(server->port()) + "/ws").c_str()
                     : "null",
              published >= 0 ? json_str(cfg.cluster_host + ":" + std::to_string(published)).c_str() : "null",
              json_str(settings->name).c_str(), kids.c_str(), cfg.renders ? "true" : "false",
              json_str(opts.web_root).c_str(), json_str(cfg.scene).c_str(), cfg.max_clients,
              cfg.render_threads > 0 ? cfg.render_threads : hardware_threads(), json_str(cpu_model()).c_str(),
              json_str(renderer).c_str(), json_str(gl_ok ? "available" : "unavailable: " + gl_why).c_str(),
              json_str(cfg.bvh_quality).c_str(),
              static_cast<unsigned long long>(settings->budget ? settings->budget->limit() : 0),
              settings->handshake_timeout_ms, admission_json(opts).c_str(),
              server && server->redirect_port()
                  ? json_str("http://" + opts.host + ":" + std::to_string(server->redirect_port()) + "/").c_str()
                  : "null",
              opts.hsts_max_age);
  std::fflush(stdout);
  int sig = 0;
  while (sigwait(&sigs, &sig) == 0 && sig == SIGHUP) {
    // A renewed certificate (docs/operations.md, "TLS"): read here, on the main thread; the
    // server logs a tls_certificate event either way and serves on.
    if (server)
      server->reload_tls();
    else
      node_log(*settings, Event(Ev::tls_certificate, "reload_failed").with("error", "no HTTP endpoint on this node"));
  }
  std::fprintf(stderr, "{\"stopping\": true, \"signal\": %d}\n", sig);
  if (server) server->stop();
  if (node) caf::anon_send_exit(node, caf::exit_reason::user_shutdown);
  sys.await_all_actors_done();
  flush_logger(sys, logger);
  stop_logger(sys, logger);
  return 0;
}

const Command reg("serve", "run a node: web client over HTTP, client protocol over WebSocket", run);

}  // namespace
}  // namespace tessera::app
