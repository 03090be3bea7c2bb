// Mutual TLS between nodes (docs/operations.md, "Running a cluster across hosts securely"), with
// real `tessera serve` processes on localhost (the built binary, TESSERA_BINARY) and certificates
// that scripts/cluster-certs.sh makes into a temporary folder at the start:
//  - a master and two workers over TLS render right, and a killed worker is covered and rejoins;
//  - a hub chain over TLS renders right, and a killed hub takes its sub-tree with it;
//  - a child with a certificate of another CA is refused by its master, a master with one by its
//    child, a child without TLS by a TLS master and a TLS child by a master without it; the
//    master logs child_unreachable with the cause and renders alone;
//  - a plain CAF peer gets no link to a TLS node, and a raw TCP client gets nothing readable;
//  - the cluster port binds to loopback by default, and bad TLS settings end serve clearly.
#include <catch2/catch.hpp>

#include <arpa/inet.h>
#include <ifaddrs.h>
#include <netinet/in.h>
#include <poll.h>
#include <signal.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cctype>
#include <chrono>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <memory>
#include <string>
#include <vector>

#include <caf/all.hpp>
#include <caf/io/all.hpp>

#include "tests/cluster/serve_node.h"
#include "tests/cluster/cluster_checks.h"
#include "tests/cluster/cluster_checks.h"
#include "tests/e2e/node_fixture.h"
#include "tests/e2e/process.h"

using namespace tessera;
using namespace tessera::test;
using protocol::DisplayKind;

namespace {

constexpr int W = 240, H = 136;

// The certificates of this run: a cluster CA with its nodes, and another CA with a node of its
// own, made by scripts/cluster-certs.sh once per process; removed at its end.
struct Certs {
  std::string base, cluster, other;
  Certs() {
    char tmpl[] = "/tmp/tessera-tls-test-XXXXXX";
    REQUIRE(mkdtemp(tmpl) != nullptr);
    base = tmpl;
    cluster = base + "/cluster";
    other = base + "/other";
    make(cluster, {"master", "hub", "w1", "w2", "w3"});
    make(other, {"rogue"});
  }
  ~Certs() {
    std::error_code ec;
    std::filesystem::remove_all(base, ec);
  }
  static void make(const std::string& dir, std::vector<std::string> names) {
    std::vector<std::string> a{"/bin/bash", TESSERA_CERTS_SCRIPT, dir};
    a.insert(a.end(), names.begin(), names.end());
    Process p(a);
    auto status = p.wait(60000);
    INFO("scripts/cluster-certs.sh: " << p.out() << p.err());
    REQUIRE(status);
    REQUIRE(WIFEXITED(*status));
    REQUIRE(WEXITSTATUS(*status) == 0);
  }
  // The settings of node `name` of the cluster CA (`ca`: another CA file to trust instead).
  std::vector<std::string> tls(const std::string& name, const std::string& ca = "") const {
    return {"--tessera.cluster-tls-cert=" + cluster + "/" + name + ".pem",
            "--tessera.cluster-tls-key=" + cluster + "/" + name + ".key",
            "--tessera.cluster-tls-ca=" + (ca.empty() ? cluster + "/ca.pem" : ca)};
  }
  // The other CA's node: its certificate and key, trusting `ca` (default: its own CA only).
  std::vector<std::string> rogue(const std::string& ca = "") const {
    return {"--tessera.cluster-tls-cert=" + other + "/rogue.pem", "--tessera.cluster-tls-key=" + other + "/rogue.key",
            "--tessera.cluster-tls-ca=" + (ca.empty() ? other + "/ca.pem" : ca)};
  }
};

const Certs& certs() {
  static Certs c;
  return c;
}

std::vector<std::string> operator+(std::vector<std::string> a, const std::vector<std::string>& b) {
  a.insert(a.end(), b.begin(), b.end());
  return a;
}

using Node = ServeNode;

Node worker(const std::string& name, const std::vector<std::string>& tls, uint16_t port = 0) {
  return Node(std::vector<std::string>{"--no-http", "--cluster-port", std::to_string(port), "--tessera.name=" + name} +
              tls);
}


// The last line of a log that holds `needle` ("" if none).
std::string last_line_with(const std::string& log, const std::string& needle) {
  auto at = log.rfind(needle);
  if (at == std::string::npos) return {};
  auto begin = log.rfind('\n', at);
  begin = begin == std::string::npos ? 0 : begin + 1;
  return log.substr(begin, log.find('\n', at) - begin);
}

size_t count(const std::string& s, const std::string& needle) {
  size_t n = 0;
  for (auto at = s.find(needle); at != std::string::npos; at = s.find(needle, at + 1)) ++n;
  return n;
}

// What a plain TCP client gets from 127.0.0.1:port: `before` within `quiet_ms` of connecting
// while it says nothing; then it sends `hello`, and `after` is what comes until the node closes
// the connection (`closed`) or `ms` pass.
struct Exchange {
  bool connected = false, closed = false;
  std::string before, after;
};
Exchange raw_exchange(uint16_t port, const std::string& hello, int quiet_ms, int ms) {
  Exchange x;
  const int fd = socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
  REQUIRE(fd >= 0);
  sockaddr_in a{};
  a.sin_family = AF_INET;
  a.sin_port = htons(port);
  a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  x.connected = connect(fd, reinterpret_cast<sockaddr*>(&a), sizeof a) == 0;
  auto read_for = [&](std::string& out, int wait_ms) {
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::milliseconds(wait_ms);
    while (!x.closed) {
      const auto left =
          std::chrono::duration_cast<std::chrono::milliseconds>(deadline - std::chrono::steady_clock::now()).count();
      pollfd p{fd, POLLIN, 0};
      if (left <= 0 || poll(&p, 1, int(left)) != 1) return;
      char buf[4096];
      const ssize_t n = recv(fd, buf, sizeof buf, 0);
      if (n <= 0) x.closed = true;
      else out.append(buf, size_t(n));
    }
  };
  if (x.connected) {
    read_for(x.before, quiet_ms);
    if (!x.closed && send(fd, hello.data(), hello.size(), MSG_NOSIGNAL) == ssize_t(hello.size())) read_for(x.after, ms);
  }
  close(fd);
  return x;
}

std::string lower(std::string s) {
  std::transform(s.begin(), s.end(), s.begin(), [](unsigned char c) { return char(std::tolower(c)); });
  return s;
}

// An IPv4 address of this machine that is not loopback ("" if none is up).
std::string non_loopback_ipv4() {
  ifaddrs* list = nullptr;
  if (getifaddrs(&list) != 0) return {};
  std::string out;
  for (ifaddrs* i = list; i && out.empty(); i = i->ifa_next)
    if (i->ifa_addr && i->ifa_addr->sa_family == AF_INET) {
      char buf[INET_ADDRSTRLEN];
      auto* in = reinterpret_cast<sockaddr_in*>(i->ifa_addr);
      if ((ntohl(in->sin_addr.s_addr) >> 24) != 127 && inet_ntop(AF_INET, &in->sin_addr, buf, sizeof buf)) out = buf;
    }
  freeifaddrs(list);
  return out;
}

bool tcp_connects(const std::string& ip, uint16_t port) {
  const int fd = socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
  if (fd < 0) return false;
  sockaddr_in a{};
  a.sin_family = AF_INET;
  a.sin_port = htons(port);
  inet_pton(AF_INET, ip.c_str(), &a.sin_addr);
  const bool ok = connect(fd, reinterpret_cast<sockaddr*>(&a), sizeof a) == 0;
  close(fd);
  return ok;
}


// The child_unreachable line of child `addr` in a master's log, once there is one.
std::string unreachable_line(Process& master, const std::string& addr) {
  const std::string needle = "\"child_unreachable\": \"" + addr + "\"";
  wait_for([&] { return master.err_count(needle) >= 1; }, 15000);
  return last_line_with(master.err(), needle);
}

}  // namespace

TEST_CASE("Over mutual TLS two workers render for a master; a killed worker is covered and rejoins",
          "[cluster][fault][tls]") {
  const Certs& c = certs();
  Node w1 = worker("w1", c.tls("w1")), w2 = worker("w2", c.tls("w2"));
  const uint16_t p1 = w1.cluster;
  Node m(std::vector<std::string>{"--port", "0", "--no-render", "--tessera.log-frames=false", "--children",
                                  w1.addr() + "," + w2.addr()} +
         c.tls("master"));
  {
    const bool connected = wait_for([&] { return m.p->err_count("\"child_connected\"") == 2; }, 20000);
    INFO("master stderr: " << m.p->err());
    REQUIRE(connected);
  }
  // Each node says it runs over mutual TLS, and the cluster port bound to loopback (no
  // cluster-host given).
  for (Node* n : {&w1, &w2, &m}) {
    // The event goes through the node's logger actor: it may reach stderr after the listening line.
    wait_for([&] { return n->p->err_count("\"cluster_security\"") >= 1; }, 10000);
    INFO("stderr: " << n->p->err());
    CHECK(n->p->err_count("\"cluster_security\": \"mutual_tls\"") == 1);
    CHECK(n->p->err_count("\"warning\"") == 0);
  }
  CHECK(json_field(w1.p->out(), "cluster").rfind("127.0.0.1:", 0) == 0);

  ProtoClient client;
  REQUIRE(client.connect(m.http));
  auto hs = client.handshake(DisplayKind::jpeg, W, H, 95);
  REQUIRE(hs);
  CHECK(hs->nodes == 2);  // a dedicated master: both workers render
  REQUIRE(client.upload(pavilion().scene));
  uint32_t n = 1;
  for (size_t k : {0, 40}) check_frame(client, k, n++, *m.p);
  {
    // Both workers rendered their tasks; the master recovered nothing.
    const std::string line = last_line_with(m.p->err(), "\"cluster_frame\": 2,");
    INFO("cluster_frame line: " << line);
    CHECK(count(line, "{\"node\": ") == 2);
    CHECK(line.find("\"recovered\": 0,") != std::string::npos);
  }
  CHECK(w1.p->err_count("\"worker_opened\"") == 1);
  CHECK(w2.p->err_count("\"worker_opened\"") == 1);

  // A worker dies mid-stream: the frames still arrive and are right.
  w1.p->signal(SIGKILL);
  for (size_t k : {100, 120}) check_frame(client, k, n++, *m.p);
  CHECK(m.p->err_count("\"node_lost\"") >= 1);

  // It comes back on the same port, over TLS again: the session reopens a worker there.
  Node back = worker("w1b", c.tls("w1"), p1);
  const bool rejoined =
      wait_for([&] { return m.p->err_count("\"joined\": \"127.0.0.1:" + std::to_string(p1)) == 2; }, 20000);
  INFO("master stderr: " << tail(m.p->err()));
  REQUIRE(rejoined);
  for (size_t k : {160, 180}) check_frame(client, k, n++, *m.p);
  CHECK(back.p->err_count("\"worker_opened\"") == 1);
  CHECK(m.p->err_count("\"error\"") == 0);
}

TEST_CASE("Over mutual TLS a hub relays a sub-tree; when it dies its sub-tree leaves", "[cluster][fault][tls]") {
  const Certs& c = certs();
  Node w3 = worker("w3", c.tls("w3"));
  Node hub(std::vector<std::string>{"--no-http", "--no-render", "--cluster-port", "0", "--tessera.name=hub",
                                    "--children", w3.addr()} +
           c.tls("hub"));
  REQUIRE(wait_for([&] { return hub.p->err_count("\"child_connected\"") == 1; }, 20000));
  Node m(std::vector<std::string>{"--port", "0", "--children", hub.addr()} + c.tls("master"));  // renders too
  REQUIRE(wait_for([&] { return m.p->err_count("\"child_connected\"") == 1; }, 20000));

  ProtoClient client;
  REQUIRE(client.connect(m.http));
  auto hs = client.handshake(DisplayKind::jpeg, W, H, 95);
  REQUIRE(hs);
  CHECK(hs->nodes == 2);  // the master, and w3 through the hub
  REQUIRE(client.upload(pavilion().scene));
  uint32_t n = 1;
  for (size_t k : {0, 50}) check_frame(client, k, n++, *m.p);
  INFO("w3 stderr: " << w3.p->err());
  CHECK(w3.p->err_count("\"worker_opened\"") >= 1);
  CHECK(w3.p->err_count("\"master\": \"hub\"") == w3.p->err_count("\"worker_opened\""));

  // The hub dies: its worker on w3 ends with its parent, and the master renders on alone.
  hub.p->signal(SIGKILL);
  CHECK(wait_for([&] { return w3.p->err_count("\"ended\": \"parent") >= 1; }, 5000));
  for (size_t k : {100, 150}) check_frame(client, k, n++, *m.p);
  CHECK(m.p->err_count("\"node_lost\": \"" + hub.addr()) >= 1);
  CHECK(m.p->err_count("\"error\"") == 0);
}

TEST_CASE("Nodes without a certificate of the cluster CA are refused both ways, and the master says why",
          "[cluster][tls]") {
  const Certs& c = certs();
  Node good = worker("good", c.tls("w1"));
  Node rogue = worker("rogue", c.rogue());      // another CA's certificate, trusting that CA
  Node plain = worker("plain", {});             // no TLS at all
  // A TLS master of the cluster CA refuses the rogue child (its certificate does not verify)
  // and the plain one (no TLS): it renders every frame alone.
  Node m(std::vector<std::string>{"--port", "0", "--children", rogue.addr() + "," + plain.addr()} + c.tls("master"));
  {
    const std::string line = unreachable_line(*m.p, rogue.addr());
    INFO("master stderr: " << m.p->err());
    CHECK(line.find("refused the child's certificate (CN = rogue)") != std::string::npos);
    CHECK(line.find("comes from another CA") != std::string::npos);
    const std::string plain_line = unreachable_line(*m.p, plain.addr());
    CHECK(plain_line.find("the child does not answer in TLS") != std::string::npos);
  }
  ProtoClient client;
  REQUIRE(client.connect(m.http));
  auto hs = client.handshake(DisplayKind::jpeg, W, H, 95);
  REQUIRE(hs);
  CHECK(hs->nodes == 1);
  REQUIRE(client.upload(pavilion().scene));
  check_frame(client, 0, 1, *m.p);
  CHECK(m.p->err_count("\"child_connected\"") == 0);

  // A master whose own certificate comes from the other CA, but which trusts both CAs: the
  // good child refuses it.
  const std::string both = c.base + "/both-cas.pem";
  {
    std::ofstream out(both);
    out << std::ifstream(c.cluster + "/ca.pem").rdbuf() << std::ifstream(c.other + "/ca.pem").rdbuf();
  }
  Node rm(std::vector<std::string>{"--port", "0", "--children", good.addr()} + c.rogue(both));
  {
    const std::string line = unreachable_line(*rm.p, good.addr());
    INFO("rogue master stderr: " << rm.p->err());
    CHECK(line.find("the child refused this node's certificate") != std::string::npos);
    CHECK(line.find("unknown ca") != std::string::npos);
  }
  // A master without TLS is refused by the TLS child.
  Node pm({"--port", "0", "--children", good.addr()});
  {
    const std::string line = unreachable_line(*pm.p, good.addr());
    INFO("plain master stderr: " << pm.p->err());
    CHECK(line.find("the child asks for mutual TLS") != std::string::npos);
  }
  // Both kept trying (every reconnect-ms) and never got through.
  std::this_thread::sleep_for(std::chrono::milliseconds(600));
  CHECK(rm.p->err_count("\"child_connected\"") == 0);
  CHECK(pm.p->err_count("\"child_connected\"") == 0);
  CHECK(m.p->err_count("\"child_connected\"") == 0);
  for (Node* w : {&good, &rogue, &plain}) {
    INFO("worker stderr: " << w->p->err());
    CHECK(w->p->err_count("\"worker_opened\"") == 0);
    CHECK(w->p->wait(0) == std::nullopt);  // still running
  }
}

TEST_CASE("A TLS node's cluster port gives a plain CAF peer no link and a raw client nothing readable",
          "[cluster][tls]") {
  const Certs& c = certs();
  Node tls = worker("secret-node", c.tls("w2"));
  Node plain = worker("open-node", {});
  // 64 bytes as a BASP header could start: whatever a plain peer says first.
  const std::string hello(64, '\0');

  // The plain port: CAF's handshake comes at once and in clear, naming the application, the
  // framework and the node's interface (so this check can fail).
  Exchange open = raw_exchange(plain.cluster, hello, 1000, 1000);
  REQUIRE(open.connected);
  CHECK(lower(open.before).find("tessera") != std::string::npos);
  CHECK(lower(open.before).find("caf") != std::string::npos);

  // The TLS port says nothing to a client that does not start a TLS handshake, and ends the
  // connection at its first bytes with at most a TLS alert.
  Exchange x = raw_exchange(tls.cluster, hello, 1000, 3000);
  REQUIRE(x.connected);
  CHECK(x.before.empty());
  CHECK(x.closed);
  CHECK(x.after.size() <= 7);  // one TLS alert record, if any
  for (const std::string& s : {x.before, x.after}) {
    CHECK(lower(s).find("tessera") == std::string::npos);
    CHECK(lower(s).find("caf") == std::string::npos);
    CHECK(lower(s).find("secret-node") == std::string::npos);
  }

  // A CAF peer with the nodes' types and identifier but the plain middleman gets no link.
  PeerConfig cfg;
  caf::actor_system sys{cfg};
  {
    caf::scoped_actor self{sys};
    bool linked = false;
    std::string error;
    self->request(sys.middleman().actor_handle(), std::chrono::seconds(10), caf::connect_atom::value,
                  std::string("127.0.0.1"), tls.cluster)
        .receive([&](const caf::node_id&, caf::strong_actor_ptr& p,
                     const std::set<std::string>&) { linked = bool(p); },
                 [&](caf::error& e) { error = sys.render(e); });
    INFO("error: " << error);
    CHECK(!linked);
    CHECK(!error.empty());
    // The same peer does link to the plain node (the refusal above is TLS's).
    linked = false;
    error.clear();
    self->request(sys.middleman().actor_handle(), std::chrono::seconds(10), caf::connect_atom::value,
                  std::string("127.0.0.1"), plain.cluster)
        .receive([&](const caf::node_id&, caf::strong_actor_ptr& p,
                     const std::set<std::string>&) { linked = bool(p); },
                 [&](caf::error& e) { error = sys.render(e); });
    INFO("error: " << error);
    CHECK(linked);
  }
  CHECK(tls.p->err_count("\"worker_opened\"") == 0);
  CHECK(tls.p->wait(0) == std::nullopt);  // still running
}

TEST_CASE("The cluster port binds to loopback unless configured; without TLS elsewhere the node warns",
          "[cluster][tls]") {
  const Certs& c = certs();
  {
    Node w = worker("w", {});
    // The event goes through the node's logger actor: it may reach stderr after the listening line.
    wait_for([&] { return w.p->err_count("\"cluster_security\"") >= 1; }, 10000);
    CHECK(json_field(w.p->out(), "cluster").rfind("127.0.0.1:", 0) == 0);
    CHECK(w.p->err_count("\"cluster_security\": \"none\"") == 1);
    CHECK(w.p->err_count("\"warning\"") == 0);  // loopback: nothing crosses the network
    const std::string ip = non_loopback_ipv4();
    if (!ip.empty()) {
      INFO("this machine's address " << ip);
      CHECK(!tcp_connects(ip, w.cluster));
    }
  }
  {
    Node w = worker("w", {"--tessera.cluster-host=0.0.0.0"});
    wait_for([&] { return w.p->err_count("\"cluster_security\"") >= 1; }, 10000);
    INFO("stderr: " << w.p->err());
    CHECK(w.p->err_count("\"cluster_security\": \"none\"") == 1);
    CHECK(w.p->err_count("\"warning\": \"no TLS on its cluster port on 0.0.0.0: scenes and frames cross the network "
                         "in clear") == 1);
  }
  {
    // Over TLS no warning about the network; a key others may read is one.
    const std::string open_key = c.base + "/w1-open.key";
    std::filesystem::copy_file(c.cluster + "/w1.key", open_key, std::filesystem::copy_options::overwrite_existing);
    chmod(open_key.c_str(), 0644);
    Node w = worker("w", {"--tessera.cluster-host=0.0.0.0", "--tessera.cluster-tls-cert=" + c.cluster + "/w1.pem",
                          "--tessera.cluster-tls-key=" + open_key, "--tessera.cluster-tls-ca=" + c.cluster + "/ca.pem"});
    wait_for([&] { return w.p->err_count("\"cluster_security\"") >= 1; }, 10000);
    INFO("stderr: " << w.p->err());
    CHECK(w.p->err_count("\"cluster_security\": \"mutual_tls\"") == 1);
    CHECK(w.p->err_count("\"warning\"") == 0);
    CHECK(w.p->err_count("may be read by other users (mode 0644): chmod 600 it") == 1);
  }
}

TEST_CASE("Bad TLS settings end serve with a clear error", "[cluster][tls]") {
  const Certs& c = certs();
  auto refused = [](std::vector<std::string> extra, const std::string& message) {
    std::vector<std::string> a{TESSERA_BINARY, "serve", "--no-http", "--cluster-port", "0"};
    a.insert(a.end(), extra.begin(), extra.end());
    Process p(a);
    auto status = p.wait(20000);
    std::string args;
    for (auto& e : extra) args += e + " ";
    INFO("args: " << args << "; stderr: " << p.err());
    REQUIRE(status);
    CHECK(WIFEXITED(*status));
    CHECK(WEXITSTATUS(*status) != 0);
    CHECK(p.err().find(message) != std::string::npos);
  };
  const std::string cert = "--tessera.cluster-tls-cert=" + c.cluster + "/w1.pem";
  const std::string key = "--tessera.cluster-tls-key=" + c.cluster + "/w1.key";
  const std::string ca = "--tessera.cluster-tls-ca=" + c.cluster + "/ca.pem";
  refused({cert}, "tessera.cluster-tls-key and tessera.cluster-tls-ca are missing");
  refused({cert, key}, "tessera.cluster-tls-ca is missing");
  refused({"--tessera.cluster-tls-cert=" + c.base + "/none.pem", key, ca},
          "tessera.cluster-tls-cert: " + c.base + "/none.pem: cannot read it: No such file or directory");
  refused({cert, "--tessera.cluster-tls-key=" + c.cluster + "/w2.key", ca}, "is not the key of the certificate");
  refused({cert, "--tessera.cluster-tls-key=" + c.cluster + "/w1.pem", ca}, "holds no unencrypted PEM private key");
  refused({cert, key, "--tessera.cluster-tls-ca=" + c.cluster + "/ca.key"}, "tessera.cluster-tls-ca: ");
  refused({cert, key, "--tessera.cluster-tls-ca=" + c.other + "/ca.pem"},
          "the certificate (CN = w1) was not signed by the CA of tessera.cluster-tls-ca " + c.other + "/ca.pem");
  // CAF's own settings of its OpenSSL module are not taken (the node sets them), nor its automatic
  // connections (a second, plain CAF port on every interface).
  const std::string caf_ssl = c.base + "/caf-openssl.ini", auto_ini = c.base + "/auto.ini";
  std::ofstream(caf_ssl) << "[openssl]\ncafile=\"" << c.cluster << "/ca.pem\"\n";
  std::ofstream(auto_ini) << "[middleman]\nenable-automatic-connections=true\n";
  refused({"--config", caf_ssl}, "openssl.cafile is CAF's own setting: set tessera.cluster-tls-cert");
  refused({"--config", auto_ini}, "middleman.enable-automatic-connections opens a second, plain CAF port");
  // The role configurations set the TLS files (absent here, under /etc/tessera/cluster/): serve
  // says which one it cannot read.
  for (const char* role : {"worker", "hub", "master"})
    refused({"--config", std::string("configs/") + role + ".ini"},
            "tessera.cluster-tls-cert: /etc/tessera/cluster/");
}
