#pragma once
// Mutual TLS between cluster nodes through CAF's OpenSSL module (docs/operations.md, "Running a
// cluster across hosts securely"). CAF reads a node's certificate, key and CA file anew for every
// connection, on its network thread, and ends the process when one cannot be read; so a node
// checks them at start with the same OpenSSL calls, and says which setting and file is wrong.
#include <cstdint>
#include <string>
#include <vector>

namespace tessera::app {

struct ClusterTlsFiles {
  std::string cert;  // tessera.cluster-tls-cert: this node's certificate (PEM, may hold a chain)
  std::string key;   // tessera.cluster-tls-key: its private key (PEM, unencrypted)
  std::string ca;    // tessera.cluster-tls-ca: the cluster CA's certificate(s) (PEM)
};

// Checks that each file is readable and holds what it must, that the key belongs to the
// certificate, and that the CA signed the certificate for TLS server and client use and it is
// valid now. Throws std::invalid_argument naming the setting, the file and what is wrong (never a
// key's content). Returns warnings: a key file that other users may read, a certificate that
// expires within 30 days.
std::vector<std::string> check_cluster_tls(const ClusterTlsFiles& files);

// Why a node cannot link to the child at host:port over CAF, when CAF's handshake was cut off
// (CAF says only "disconnect_during_handshake"): a TLS handshake of its own, as this node would
// make it (`files`: its certificate, key and CA; all empty for a node without TLS, which then
// learns whether the child asks for TLS), within `timeout_ms`. Returns the verdict in words for
// the operator ("the child's certificate ... was not signed by this node's cluster CA ..."), or
// "" when TLS is not the cause. Blocks: call it off the actors' threads.
std::string diagnose_cluster_link(const std::string& host, uint16_t port, const ClusterTlsFiles& files,
                                  int timeout_ms = 3000);

}  // namespace tessera::app
