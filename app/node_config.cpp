#include "app/node_config.h"

#include <stdexcept>

#include <unistd.h>

#include <caf/all.hpp>
#include <caf/io/middleman.hpp>
#include <caf/openssl/manager.hpp>

#include "app/cluster_tls.h"
#include "app/common.h"
#include "codecs/h264.h"
#include "core/gltf_loader.h"

namespace tessera::app {

namespace {

// An option whose meta state is ours. CAF's make_config_option<T> keeps it in a function-local
// static of a template that libcaf_core (built by g++) instantiates too; in a clang-built binary
// the two copies of that static and its guard disagree, and parsing `--tessera.NAME=VALUE` on
// the command line called a null function pointer in config_option::parse for lists
// (`--tessera.web-public=[...]`, under ASan and TSan) and strings (`--tessera.name=x`, under
// TSan); tests/e2e/test_serve_process.cpp caught both. One static per T, in this binary only.
template <class T>
caf::config_option own_option(T& storage, caf::string_view category, caf::string_view name, caf::string_view description,
                              std::string type_name = caf::select_config_value_access_t<T>::type_name()) {
  static caf::config_option::meta_state meta{caf::detail::check_impl<T>, caf::detail::store_impl<T>,
                                             caf::detail::get_impl<T>, caf::detail::parse_impl_delegate<T>, type_name};
  return {category, name, description, &meta, &storage};
}

caf::config_option string_list_option(std::vector<std::string>& storage, caf::string_view category,
                                      caf::string_view name, caf::string_view description) {
  return own_option(storage, category, name, description);
}

caf::config_option string_option(std::string& storage, caf::string_view category, caf::string_view name,
                                 caf::string_view description) {
  return own_option(storage, category, name, description);
}

// A boolean setting that the command line can set either way. CAF 0.17 makes a bool option a
// flag: `--tessera.log-frames=false` is a parser error there, and a bare flag is not a
// `--tessera.NAME=VALUE` argument, so such settings could only be turned off in a config file.
// With this meta state (not named "boolean", so not a flag) `=true` and `=false` both parse.
caf::config_option bool_option(bool& storage, caf::string_view category, caf::string_view name,
                               caf::string_view description) {
  return own_option(storage, category, name, description, "bool");
}

}  // namespace

NodeConfig::NodeConfig() {
  register_message_types(*this);
  // The ray tracer and the DXT1 encoder run on TBB in this process: keep CAF's scheduler small.
  set("scheduler.max-threads", size_t{2});
  // What CAF's handshake tells a peer about the application (cluster_protocol.h).
  set("middleman.app-identifiers", std::vector<std::string>{kCafAppIdentifier});
  opt_group{custom_options_, "tessera"}
      .add(port, "port", "TCP port of HTTP + WebSocket (0: any free port)")
      .add(max_clients, "max-clients", "simultaneous WebSocket clients")
      .add(render_threads, "render-threads", "TBB threads for rendering and encoding (0: all)")
      .add(logical_cores, "logical-cores", "renderer coefficient: logical cores (0: hardware threads)")
      .add(single_core_perf, "single-core-perf", "renderer coefficient: single-core performance")
      .add(max_width, "max-width", "largest frame width")
      .add(max_height, "max-height", "largest frame height")
      .add(max_message_bytes, "max-message-bytes", "largest WebSocket message")
      .add(max_buffer_bytes, "max-buffer-bytes", "largest buffer (inflated)")
      .add(max_client_bytes, "max-client-bytes", "buffers + textures held per client")
      .add(max_triangles, "max-triangles", "triangles per client scene")
      .add(max_texture_size, "max-texture-size", "largest texture width/height")
      .add(refine_samples, "refine-samples",
           "samples per pixel a still refines to after a requested frame, for clients that do not say (0: none)")
      .add(still_ao_samples, "still-ao-samples",
           "AO rays per hit in each sample of a refining still after the requested frame, for sessions with AO on "
           "(0: the session's own count)")
      .add(denoise_below_db, "denoise-below-db",
           "a refining still with AO under a sky is denoised while its estimated PSNR is below this (dB, 0..99; 0: never)")
      .add(adaptive_round, "adaptive-round",
           "a refining still's rounds after its first 4 samples render the blocks where a sample helps most, this "
           "share of a whole sample's cost each (0..1; 0: every pixel every round)")
      .add(video_kbps, "video-kbps",
           "H.264 display: the bitrate (kbit/s) for clients that do not say (100..200000)")
      .add(frame_budget_ms, "frame-budget-ms",
           "interactive frames are rendered at a lower resolution to take about this long (0: never)")
      .add(still_delay_ms, "still-delay-ms",
           "the full-resolution still after interactive frames starts this long after the last one, unless a "
           "request comes first (0..10000; 0: at once)")
      .add(handshake_timeout_ms, "handshake-timeout-ms", "close a WebSocket without a valid handshake after this long")
      .add(max_node_bytes, "max-node-bytes",
           "memory budget over all clients: scene bytes + queued frames (0: half the physical memory)")
      .add(max_mjpeg_per_session, "max-mjpeg-per-session", "MJPEG viewers of one session")
      .add(max_mjpeg_viewers, "max-mjpeg-viewers", "MJPEG viewers on the node")
      .add(max_connections_per_ip, "max-connections-per-ip", "WebSocket connections per client address (0: no limit)")
      .add(hsts_max_age, "hsts-max-age",
           "with TLS: send Strict-Transport-Security with this max-age in seconds (0: off; it pins the host name, "
           "every port, to https in browsers)")
      .add(http_redirect_port, "http-redirect-port",
           "with TLS: also listen on this port in plain HTTP, redirecting every GET/HEAD to https (0: off)")
      .add(asset_cache_mb, "asset-cache-mb", "decoded textures of references kept for later sessions, in MiB (0: none)")
      .add(asset_max_file_mb, "asset-max-file-mb", "the largest file a reference may name, in MiB")
      .add(geometry_cache_mb, "geometry-cache-mb",
           "meshes' BVHs kept for later sessions of the same geometry, in MiB (0: only while in use)")
      .add(cluster_port, "cluster-port", "publish this node to parent nodes on this port (-1: off, 0: any)")
      .add(task_timeout_ms, "task-timeout-ms", "fail a sub-tree that has not returned its tiles after this long")
      .add(reconnect_ms, "reconnect-ms", "retry period for lost child nodes; keep-alive period to workers below")
      .add(max_workers, "max-workers", "live session workers on this node; more opens are refused (0: 2 x max-clients)")
      .add(max_update_bytes, "max-update-bytes", "the largest scene update a worker takes from its parent (chunks)")
      .add(keepalive_misses, "keepalive-misses",
           "a worker whose parent sent nothing for this many keep-alive periods ends itself");
  // Strings through our own meta state, like the lists (string_option).
  custom_options_.add(string_option(host, "tessera", "host", "listen address (default 127.0.0.1: local only)"));
  custom_options_.add(string_option(web_root, "tessera", "web-root", "folder served over HTTP (web client, demo pages)"));
  custom_options_.add(string_option(scene, "tessera", "scene", "glTF scene given to clients that connect with an empty scene"));
  custom_options_.add(string_option(bvh_quality, "tessera", "bvh-quality",
                                    "meshes' BVHs: medium (default) or high (Embree's spatial splits: builds 2.5-5x slower, docs/results/load.md)"));
  custom_options_.add(string_option(token_key, "tessera", "token-key", "key file of signed access tokens (tessera token); a token is then required"));
  custom_options_.add(string_option(token_file, "tessera", "token-file", "static access tokens, one per line; a token is then required"));
  custom_options_.add(string_option(tls_cert, "tessera", "tls-cert", "PEM certificate (chain) of the port: HTTPS and WSS only (with tls-key)"));
  custom_options_.add(string_option(tls_key, "tessera", "tls-key", "PEM private key of tls-cert"));
  custom_options_.add(string_option(tcp_congestion, "tessera", "tcp-congestion",
                                    "TCP congestion control of the port's connections, e.g. bbr (docs/operations.md); "
                                    "empty: the system's default"));
  custom_options_.add(string_option(cluster_host, "tessera", "cluster-host", "address of the cluster port (0.0.0.0: all interfaces)"));
  custom_options_.add(string_option(name, "tessera", "name", "this node's name in node lists and logs (default host:cluster-port)"));
  custom_options_.add(string_option(cluster_tls_cert, "tessera", "cluster-tls-cert",
                                    "this node's certificate (PEM) for mutual TLS between nodes, signed by the cluster CA"));
  custom_options_.add(string_option(cluster_tls_key, "tessera", "cluster-tls-key",
                                    "the private key (PEM, unencrypted) of cluster-tls-cert"));
  custom_options_.add(string_option(cluster_tls_ca, "tessera", "cluster-tls-ca",
                                    "the cluster CA's certificate (PEM): peers must present a certificate it signed"));
  custom_options_.add(string_list_option(
      web_public, "tessera", "web-public",
      "further folders of the web root to serve, as [\"dir/\", ...] (default: index.html, src/, demo/, three.js)"));
  custom_options_.add(string_list_option(
      allowed_origins, "tessera", "allowed-origins",
      "page origins that may open sessions, as [\"https://app.example.com\", \"self\", \"loopback\"] or [\"*\"] "
      "(default: self and loopback)"));
  custom_options_.add(string_list_option(
      asset_origins, "tessera", "asset-origins",
      "origins whose URLs the node fetches when a client references them, as [\"https://cdn.example\"] "
      "(default: none; files of the node's own /scenes/ are always read)"));
  custom_options_.add(bool_option(require_origin, "tessera", "require-origin",
                                  "refuse WebSocket requests without an Origin header (non-browser clients)"));
  custom_options_.add(bool_option(log_frames, "tessera", "log-frames", "log one JSON line per frame"));
  custom_options_.add(bool_option(reproject, "tessera", "reproject",
                                  "balance each frame from the last frame's cost carried into its camera (false: as it is)"));
  custom_options_.add(bool_option(renders, "tessera", "render", "render tasks here (false: hub or dedicated master)"));
  custom_options_.add(bool_option(http, "tessera", "http", "serve HTTP and WebSocket clients (false: worker or hub only)"));
  custom_options_.add(string_list_option(children, "tessera", "children", "child nodes as [\"host:port\", ...]"));
}

std::vector<std::string> NodeConfig::load_cluster_modules() {
  std::vector<std::string> warnings;
  // CAF's own openssl.* settings would turn its OpenSSL module's authentication on or off
  // behind the node's back (any one of them set enables it): the node sets them itself.
  for (const auto& [setting, value] : {std::pair<const char*, const std::string*>{"certificate", &openssl_certificate},
                                       {"key", &openssl_key},
                                       {"passphrase", &openssl_passphrase},
                                       {"capath", &openssl_capath},
                                       {"cafile", &openssl_cafile}})
    if (!value->empty())
      throw std::invalid_argument(std::string("openssl.") + setting +
                                  " is CAF's own setting: set tessera.cluster-tls-cert, cluster-tls-key and "
                                  "cluster-tls-ca instead");
  // CAF's automatic connections open a second CAF port, plain and on every interface.
  if (caf::get_or(*this, "middleman.enable-automatic-connections", false))
    throw std::invalid_argument(
        "middleman.enable-automatic-connections opens a second, plain CAF port on every interface: not supported "
        "(nodes connect only to the children they name)");
  const int set = int(!cluster_tls_cert.empty()) + int(!cluster_tls_key.empty()) + int(!cluster_tls_ca.empty());
  if (set != 0 && set != 3) {
    std::string missing;
    for (const auto& [setting, value] : {std::pair<const char*, const std::string*>{"cluster-tls-cert", &cluster_tls_cert},
                                         {"cluster-tls-key", &cluster_tls_key},
                                         {"cluster-tls-ca", &cluster_tls_ca}})
      if (value->empty()) missing += (missing.empty() ? "tessera." : " and tessera.") + std::string(setting);
    throw std::invalid_argument("mutual TLS between nodes needs tessera.cluster-tls-cert, cluster-tls-key and "
                                "cluster-tls-ca: " + missing + (set == 2 ? " is" : " are") + " missing");
  }
  if (set == 3) warnings = check_cluster_tls(ClusterTlsFiles{cluster_tls_cert, cluster_tls_key, cluster_tls_ca});
  if (!cluster()) return warnings;
  load<caf::io::middleman>();
  if (cluster_tls()) {
    // CAF's OpenSSL module with these settings requires a certificate the CA signed from every
    // peer, on both ends of a connection (SSL_VERIFY_PEER | SSL_VERIFY_FAIL_IF_NO_PEER_CERT).
    openssl_certificate = cluster_tls_cert;
    openssl_key = cluster_tls_key;
    openssl_cafile = cluster_tls_ca;
    load<caf::openssl::manager>();
  }
  return warnings;
}

std::shared_ptr<NodeSettings> NodeConfig::node_settings() const {
  auto s = std::make_shared<NodeSettings>();
  auto positive = [](int64_t v, const char* name) {
    if (v <= 0) throw std::invalid_argument(std::string("tessera.") + name + " must be > 0");
    return v;
  };
  s->limits.max_width = int32_t(positive(max_width, "max-width"));
  s->limits.max_height = int32_t(positive(max_height, "max-height"));
  s->limits.max_message_bytes = uint32_t(std::min<int64_t>(positive(max_message_bytes, "max-message-bytes"), 0xffffffffll));
  s->limits.max_buffer_bytes = uint64_t(positive(max_buffer_bytes, "max-buffer-bytes"));
  s->limits.max_client_bytes = uint64_t(positive(max_client_bytes, "max-client-bytes"));
  s->limits.max_message_payload_bytes = std::max<uint64_t>(s->limits.max_message_payload_bytes, s->limits.max_buffer_bytes);
  s->limits.max_triangles = uint64_t(positive(max_triangles, "max-triangles"));
  s->limits.max_texture_size = int32_t(positive(max_texture_size, "max-texture-size"));
  s->coefficient.logical_cores = logical_cores > 0 ? logical_cores : (render_threads > 0 ? render_threads : hardware_threads());
  s->coefficient.single_core_perf = single_core_perf;
  if (!(single_core_perf > 0)) throw std::invalid_argument("tessera.single-core-perf must be > 0");
  if (!scene.empty()) {
    LoadedScene loaded = load_gltf(scene);
    for (auto& w : loaded.warnings) std::fprintf(stderr, "warning: %s\n", w.c_str());
    if (const std::string note = lighting_note(scene, loaded); !note.empty()) std::fprintf(stderr, "note: %s\n", note.c_str());
    s->preload = std::make_shared<const Scene>(std::move(loaded.scene));
  }
  if (task_timeout_ms < 50) throw std::invalid_argument("tessera.task-timeout-ms must be >= 50");
  if (reconnect_ms < 10 || reconnect_ms > 60000) throw std::invalid_argument("tessera.reconnect-ms must be in 10..60000");
  if (cluster_port < -1 || cluster_port > 65535) throw std::invalid_argument("tessera.cluster-port must be in -1..65535");
  if (handshake_timeout_ms < 10) throw std::invalid_argument("tessera.handshake-timeout-ms must be >= 10");
  if (max_node_bytes < 0) throw std::invalid_argument("tessera.max-node-bytes must be >= 0 (0: half the physical memory)");
  s->handshake_timeout_ms = uint32_t(handshake_timeout_ms);
  if (refine_samples < 0 || uint32_t(refine_samples) > s->limits.max_refine_samples)
    throw std::invalid_argument("tessera.refine-samples must be in 0.." + std::to_string(s->limits.max_refine_samples));
  s->refine_samples = uint32_t(refine_samples);
  if (still_ao_samples < 0 || uint32_t(still_ao_samples) > s->limits.max_ao_samples)
    throw std::invalid_argument("tessera.still-ao-samples must be in 0.." + std::to_string(s->limits.max_ao_samples));
  s->still_ao_samples = uint32_t(still_ao_samples);
  if (!(denoise_below_db >= 0 && denoise_below_db <= 99))
    throw std::invalid_argument("tessera.denoise-below-db must be in 0..99");
  s->denoise_below_db = denoise_below_db;
  if (!(adaptive_round >= 0 && adaptive_round <= 1)) throw std::invalid_argument("tessera.adaptive-round must be in 0..1");
  s->adaptive_round = adaptive_round;
  if (video_kbps < int(kH264MinKbps) || video_kbps > int(kH264MaxKbps))
    throw std::invalid_argument("tessera.video-kbps must be in " + std::to_string(kH264MinKbps) + ".." +
                                std::to_string(kH264MaxKbps));
  s->video_kbps = uint32_t(video_kbps);
  if (frame_budget_ms < 0 || frame_budget_ms > 60000) throw std::invalid_argument("tessera.frame-budget-ms must be in 0..60000");
  s->frame_budget_ms = uint32_t(frame_budget_ms);
  if (still_delay_ms < 0 || still_delay_ms > 10000) throw std::invalid_argument("tessera.still-delay-ms must be in 0..10000");
  s->still_delay_ms = uint32_t(still_delay_ms);
  s->budget = std::make_shared<MemoryBudget>(max_node_bytes > 0 ? uint64_t(max_node_bytes) : MemoryBudget::default_limit());
  s->render = renders;
  s->reproject = reproject;
  s->children = children;
  s->task_timeout_ms = uint32_t(task_timeout_ms);
  s->reconnect_ms = uint32_t(reconnect_ms);
  if (max_workers < 0 || max_workers > 100000) throw std::invalid_argument("tessera.max-workers must be in 0..100000");
  if (max_clients < 1) throw std::invalid_argument("tessera.max-clients must be >= 1");
  s->max_workers = uint32_t(max_workers > 0 ? max_workers : 2 * std::min(max_clients, 50000));
  if (keepalive_misses < 2 || keepalive_misses > 1000)
    throw std::invalid_argument("tessera.keepalive-misses must be in 2..1000");
  s->keepalive_misses = uint32_t(keepalive_misses);
  if (max_update_bytes < 1 || uint64_t(max_update_bytes) > kMaxPeerBytes)
    throw std::invalid_argument("tessera.max-update-bytes must be in 1.." + std::to_string(kMaxPeerBytes));
  s->max_update_bytes = uint64_t(max_update_bytes);
  s->cluster_tls = cluster_tls();
  // A child whose CAF handshake is cut off: a TLS handshake as this node would make it says
  // whether TLS is why (a child without TLS, or one of another CA).
  s->diagnose_link = [files = ClusterTlsFiles{cluster_tls_cert, cluster_tls_key, cluster_tls_ca}](
                         const std::string& host, uint16_t port) { return diagnose_cluster_link(host, port, files); };
  s->name = !name.empty() ? name
            : cluster_port > 0  ? cluster_host + ":" + std::to_string(cluster_port)
            : cluster_port == 0 ? cluster_host + ":any/pid" + std::to_string(getpid())
                                : "local";
  // Without per-frame lines: every event but Ev::frame (the old substring filter on "frame"
  // also hid the recovering events, which carry the frame number).
  if (!log_frames) s->log = [](const Event& e) {
    if (e.kind != Ev::frame) std::fprintf(stderr, "%s\n", to_json_line(e).c_str());
  };
  return s;
}

Event cluster_security_event(const NodeConfig& cfg, const std::string& name, int published,
                             const std::vector<std::string>& warnings) {
  Event e(Ev::cluster_security, cfg.cluster_tls() ? "mutual_tls" : "none");
  e.scope = {{"node", name}};
  e.with("endpoint", published >= 0 ? Json(cfg.cluster_host + ":" + std::to_string(published)) : Json());
  if (cfg.cluster_tls()) {
    e.with("ca", cfg.cluster_tls_ca).with("cert", cfg.cluster_tls_cert);
  } else {
    // A cluster address on this machine's loopback is out of other machines' reach.
    auto loopback = [](std::string host) {
      if (host.size() > 2 && host.front() == '[' && host.back() == ']') host = host.substr(1, host.size() - 2);
      return admission::loopback_host(host);
    };
    std::vector<std::string> open;
    if (published >= 0 && !loopback(cfg.cluster_host)) open.push_back("its cluster port on " + cfg.cluster_host);
    for (const std::string& c : cfg.children)
      if (!loopback(c.substr(0, c.rfind(':')))) open.push_back("child " + c);
    std::string list;
    for (const std::string& o : open) list += (list.empty() ? "" : ", ") + o;
    if (!open.empty())
      e.with("warning", "no TLS on " + list +
                            ": scenes and frames cross the network in clear, and whoever reaches a cluster port can "
                            "open workers on it; set tessera.cluster-tls-cert, cluster-tls-key and cluster-tls-ca "
                            "(docs/operations.md, \"Running a cluster across hosts securely\")");
  }
  if (!warnings.empty()) {
    std::vector<Json> w(warnings.begin(), warnings.end());
    e.with("warnings", Json::array(std::move(w)));
  }
  return e;
}

ServerOptions NodeConfig::server_options() const {
  if (port < 0 || port > 65535) throw std::invalid_argument("port must be in 0..65535");
  if (max_clients < 1) throw std::invalid_argument("tessera.max-clients must be >= 1");
  ServerOptions o;
  o.host = host;
  o.port = uint16_t(port);
  o.web_root = web_root;
  for (const std::string& p : web_public) {
    if (p.empty() || p.back() != '/' || p.front() == '/' || p.find("..") != std::string::npos)
      throw std::invalid_argument("tessera.web-public: '" + p + "' is not a relative folder ending in '/'");
    o.web_public.push_back(p);
  }
  o.max_clients = size_t(max_clients);
  if (max_mjpeg_per_session < 1) throw std::invalid_argument("tessera.max-mjpeg-per-session must be >= 1");
  if (max_mjpeg_viewers < 1) throw std::invalid_argument("tessera.max-mjpeg-viewers must be >= 1");
  o.max_mjpeg_per_session = size_t(max_mjpeg_per_session);
  o.max_mjpeg_viewers = size_t(max_mjpeg_viewers);
  set_admission(o);
  if (tls_cert.empty() != tls_key.empty())
    throw std::invalid_argument("tessera.tls-cert and tessera.tls-key go together: give both (HTTPS and WSS) or neither");
  o.tls_cert = tls_cert;
  o.tls_key = tls_key;
  if (hsts_max_age < 0) throw std::invalid_argument("tessera.hsts-max-age must be >= 0 (seconds; 0: off)");
  if (hsts_max_age > 0 && !o.tls())
    throw std::invalid_argument("tessera.hsts-max-age needs TLS (tessera.tls-cert and tessera.tls-key): browsers ignore "
                                "Strict-Transport-Security over plain HTTP (behind a TLS proxy, set it at the proxy)");
  o.hsts_max_age = uint32_t(hsts_max_age);
  if (tcp_congestion.size() > 15) throw std::invalid_argument("tessera.tcp-congestion: at most 15 characters");
  o.tcp_congestion = tcp_congestion;
  if (http_redirect_port < 0 || http_redirect_port > 65535)
    throw std::invalid_argument("tessera.http-redirect-port must be in 0..65535 (0: off)");
  if (http_redirect_port > 0) {
    if (!o.tls())
      throw std::invalid_argument("tessera.http-redirect-port needs TLS (tessera.tls-cert and tessera.tls-key): it "
                                  "redirects plain HTTP to https:// on tessera.port");
    if (http_redirect_port == port)
      throw std::invalid_argument("tessera.http-redirect-port must differ from the port (" + std::to_string(port) +
                                  "), which speaks TLS");
    o.http_redirect_port = uint16_t(http_redirect_port);
  }
  return o;
}

namespace {

// Runs `read`, naming the setting in its error (which names files, never their content).
template <class F>
auto for_setting(const char* setting, F&& read) {
  try {
    return read();
  } catch (const std::invalid_argument& e) {
    throw std::invalid_argument(std::string("tessera.") + setting + ": " + e.what());
  }
}

}  // namespace

void NodeConfig::set_admission(ServerOptions& o) const {
  if (!token_key.empty()) o.tokens.set_key(for_setting("token-key", [&] { return admission::read_key_file(token_key); }));
  if (!token_file.empty())
    for (const std::string& t : for_setting("token-file", [&] { return admission::read_token_file(token_file); }))
      o.tokens.add_static(t);
  o.origins = admission::OriginPolicy::parse(allowed_origins, require_origin);
  if (max_connections_per_ip < 0) throw std::invalid_argument("tessera.max-connections-per-ip must be >= 0 (0: no limit)");
  if (asset_cache_mb < 0) throw std::invalid_argument("tessera.asset-cache-mb must be >= 0");
  if (asset_max_file_mb < 1) throw std::invalid_argument("tessera.asset-max-file-mb must be >= 1");
  if (geometry_cache_mb < 0) throw std::invalid_argument("tessera.geometry-cache-mb must be >= 0");
  if (bvh_quality != "high" && bvh_quality != "medium")
    throw std::invalid_argument("tessera.bvh-quality must be high or medium, not '" + bvh_quality + "'");
  o.max_connections_per_ip = size_t(max_connections_per_ip);
}

}  // namespace tessera::app
