#pragma once
// The node's configuration: CAF's actor_system_config with a [tessera] group, read from an
// INI file (--config configs/single.ini) and the command line (--tessera.NAME=VALUE), then
// the plain flags of `tessera serve` (--host, --port, --web-root, --scene, --threads).
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include <caf/actor_system_config.hpp>

#include "actors/node.h"
#include "net/server.h"

namespace tessera::app {

struct NodeConfig : caf::actor_system_config {
  std::string host = "127.0.0.1";
  int port = 8080;
  std::string web_root = "web";
  std::vector<std::string> web_public;  // further public folders of the web root ("dir/")
  std::string scene;            // preloaded for clients that connect with an empty scene
  int max_clients = 16;
  int render_threads = 0;       // TBB threads (0: all hardware threads)
  int logical_cores = 0;        // renderer coefficient: logical cores (0: hardware threads)
  double single_core_perf = 1;  //   x single-core performance
  int max_width = 7680, max_height = 4320;
  int64_t max_message_bytes = 64ll << 20;
  int64_t max_buffer_bytes = 256ll << 20;
  int64_t max_client_bytes = 1ll << 30;
  int64_t max_triangles = 20'000'000;
  int max_texture_size = 8192;
  bool log_frames = true;
  // Resource bounds (docs/operations.md, "Resource bounds").
  int refine_samples = 0;   // a still's samples per pixel for clients that send no refine record
  int still_ao_samples = sampling::kStillAoSamples;  // AO rays per hit in a still's later samples (0: the session's)
  double denoise_below_db = kDenoiseBelowDb;  // a refining still is denoised below this PSNR (0: never)
  double adaptive_round = AdaptiveOptions{}.round_cost;  // a still's adaptive rounds, of a sample's cost (0: off)
  int video_kbps = 8000;
  int frame_budget_ms = 0;
  int still_delay_ms = 50;  // the still after interactive frames waits this long for a request (0: none)  // interactive frames scaled to take about this long (0: never scaled)
  int handshake_timeout_ms = 5000;  // a WebSocket without a valid handshake by then is closed
  int64_t max_node_bytes = 0;       // node-wide memory budget over all clients (0: half the physical memory)
  int max_mjpeg_per_session = 4;    // MJPEG viewers of one session
  int max_mjpeg_viewers = 64;       // MJPEG viewers on the node
  // Session admission (docs/operations.md, "Admission"): who may open sessions and streams.
  std::string token_key;    // key file of signed access tokens ("": none)
  std::string token_file;   // static access tokens, one per line ("": none)
  std::string tls_cert;     // PEM certificate (chain) of HTTPS/WSS on the port ("": plain HTTP)
  std::string tls_key;      // its PEM private key
  std::string tcp_congestion;  // TCP congestion control of the port's connections ("": the system's)
  int hsts_max_age = 0;        // with TLS: Strict-Transport-Security max-age in seconds (0: not sent)
  int http_redirect_port = 0;  // with TLS: plain HTTP here redirects to https (0: off)
  std::vector<std::string> allowed_origins{"self", "loopback"};  // page origins ("*": any)
  bool require_origin = false;     // refuse WebSocket requests without an Origin header (non-browsers)
  int max_connections_per_ip = 0;  // WebSocket connections per client address (0: no limit)
  // References (docs/operations.md, "References"): what the node loads itself for its clients.
  std::vector<std::string> asset_origins;  // origins fetched over HTTP(S) besides the node's own /scenes/
  int64_t asset_cache_mb = 512;             // decoded textures kept for later sessions
  int64_t asset_max_file_mb = 1024;         // the largest file a reference may name
  int64_t geometry_cache_mb = 1024;         // meshes' BVHs kept for later sessions (renderer/geometry_cache.h)
  std::string bvh_quality = "medium";       // of the meshes' BVHs: medium or high (EmbreeDevice::set_high_quality_bvh)
  // Cluster (docs/operations.md): this node's CAF endpoint and its children.
  int cluster_port = -1;          // publish the node actor here (-1: not a child of anyone; 0: any port)
  std::string cluster_host = "127.0.0.1";  // address the cluster port binds to
  std::vector<std::string> children;       // "host:port" of child nodes
  bool renders = true;            // false: hub or dedicated master
  bool reproject = true;          // the balancer reprojects the last frame's cost (NodeSettings::reproject)
  bool http = true;               // false: no HTTP/WebSocket endpoint (a worker or hub only)
  std::string name;               // in node lists and logs (default host:cluster-port)
  int task_timeout_ms = 5000;
  int reconnect_ms = 1000;        // also the period of the keep-alives sent to workers below
  int max_workers = 0;            // live workers on this node (0: 2 x max-clients)
  int keepalive_misses = 10;      // a worker ends after this many keep-alive periods of silence
  int64_t max_update_bytes = int64_t(kMaxPeerBytes);  // the largest scene update a worker takes
  // Mutual TLS between nodes (docs/operations.md, "Running a cluster across hosts securely"):
  // all three or none; scripts/cluster-certs.sh makes them.
  std::string cluster_tls_cert;  // this node's certificate (PEM), signed by the cluster CA
  std::string cluster_tls_key;   // its private key (PEM, unencrypted)
  std::string cluster_tls_ca;    // the cluster CA's certificate: peers must show one it signed
  bool cluster() const { return cluster_port >= 0 || !children.empty(); }
  bool cluster_tls() const { return !cluster_tls_cert.empty(); }  // after load_cluster_modules

  NodeConfig();
  // Loads CAF's middleman when the node is in a cluster, and CAF's OpenSSL module over it when
  // the node has its TLS files, which are checked first (app/cluster_tls.h) and handed to the
  // module as its openssl.* settings. Call after parse, before the actor system starts. Throws
  // std::invalid_argument (a setting missing, a file unreadable, a certificate the CA did not
  // sign, CAF's own openssl.* settings or automatic connections set); returns warnings.
  std::vector<std::string> load_cluster_modules();
  // Fills NodeSettings and ServerOptions (limits checked, key and token files read; throws
  // std::invalid_argument).
  std::shared_ptr<NodeSettings> node_settings() const;
  ServerOptions server_options() const;

 private:
  void set_admission(ServerOptions& o) const;
};

// The node's start-up event on its cluster links (Ev::cluster_security, scope {"node": name}):
// "mutual_tls" with the CA and certificate files, or "none" with a warning when the cluster port
// or a child is not on loopback (scenes and frames then cross the network in clear);
// `published`: the bound cluster port (-1: none); `warnings`: load_cluster_modules's.
Event cluster_security_event(const NodeConfig& cfg, const std::string& name, int published,
                             const std::vector<std::string>& warnings);

}  // namespace tessera::app
