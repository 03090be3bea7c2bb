// Two hosts on one machine: each worker runs in its own Linux network namespace, joined to the
// root namespace by a veth pair (10.213.K.1 outside, 10.213.K.2 inside), and a dedicated
// master in the root namespace names them by those addresses. Frames streamed through the
// master must match the ray tracer's direct render while one link is cut (the interface inside
// the namespace goes down: the process lives on and its TCP connection stays open, so the
// master only notices when the task timeout expires: the part is late and rendered by the
// master, and a worker that does not answer a ping within another timeout is lost) and after
// the link comes back (the master reopens a worker on it). The same again over mutual TLS, with
// certificates that scripts/cluster-certs.sh makes at the start.
//
// Needs root (CAP_NET_ADMIN, and CAP_SYS_ADMIN for `ip netns exec`) and iproute2's `ip`.
// Without them, or with TESSERA_NO_NETNS=1, it prints why and exits 77 (CTest: skipped).
#include <catch2/catch.hpp>

#include "tests/catch_runner.h"

#include <errno.h>
#include <fcntl.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cctype>
#include <cstdio>
#include <cstdlib>
#include <memory>
#include <sstream>
#include <string>
#include <vector>

#include "tests/cluster/cluster_checks.h"
#include "tests/e2e/node_fixture.h"
#include "tests/e2e/process.h"

using namespace tessera;
using namespace tessera::test;
using protocol::DisplayKind;

namespace {

constexpr int W = 240, H = 136;
constexpr int kClusterPort = 4100;  // the same in both namespaces: each has its own ports
// The first frame of a worker decodes the scene and builds its BVH: on a loaded two-core
// machine that takes more than 1.5 s, which would fail both workers before the cut.
constexpr int kTaskTimeoutMs = 3000, kReconnectMs = 200;

// iproute2's `ip`, by absolute path (Process uses execv).
std::string ip_binary() {
  for (const char* p : {"/usr/sbin/ip", "/sbin/ip", "/usr/bin/ip", "/bin/ip"})
    if (access(p, X_OK) == 0) return p;
  return {};
}

struct CmdResult {
  int status = -1;  // exit code; -1 when it did not exit normally
  std::string output;  // stdout and stderr
};

// Runs argv (argv[0] an absolute path) to completion.
CmdResult run_cmd(const std::vector<std::string>& argv) {
  CmdResult r;
  int fds[2];
  if (pipe(fds) != 0) return r;
  pid_t pid = fork();
  if (pid < 0) {
    close(fds[0]);
    close(fds[1]);
    return r;
  }
  if (pid == 0) {
    int null = open("/dev/null", O_RDONLY);
    if (null >= 0) dup2(null, 0);
    dup2(fds[1], 1);
    dup2(fds[1], 2);
    close(fds[0]);
    close(fds[1]);
    std::vector<char*> a;
    for (auto& s : argv) a.push_back(const_cast<char*>(s.c_str()));
    a.push_back(nullptr);
    execv(a[0], a.data());
    _exit(127);
  }
  close(fds[1]);
  char buf[1024];
  ssize_t n;
  while ((n = read(fds[0], buf, sizeof buf)) > 0 || (n < 0 && errno == EINTR))
    if (n > 0) r.output.append(buf, size_t(n));
  close(fds[0]);
  int st = 0;
  while (waitpid(pid, &st, 0) < 0 && errno == EINTR) {
  }
  r.status = WIFEXITED(st) ? WEXITSTATUS(st) : -1;
  return r;
}

// `ip ARGS...`: empty on success, else the command and what it said.
std::string ip(std::vector<std::string> args) {
  args.insert(args.begin(), ip_binary());
  CmdResult r = run_cmd(args);
  if (r.status == 0) return {};
  std::string cmd;
  for (auto& a : args) cmd += (cmd.empty() ? "" : " ") + a;
  while (!r.output.empty() && (r.output.back() == '\n' || r.output.back() == ' ')) r.output.pop_back();
  return "`" + cmd + "` failed (" + std::to_string(r.status) + "): " + r.output;
}

// Namespaces of this test are tsr<pid><letter>, their root-side veth ends tsr<pid><letter>h.
// Those of a run that died without cleaning up (killed on a CTest timeout) are removed.
void remove_stale() {
  auto stale_pid = [](const std::string& name) -> bool {
    if (name.rfind("tsr", 0) != 0) return false;
    size_t end = 3;
    while (end < name.size() && std::isdigit(static_cast<unsigned char>(name[end]))) ++end;
    if (end == 3 || end > 12 || end >= name.size()) return false;
    const pid_t pid = pid_t(std::stol(name.substr(3, end - 3)));
    return pid != getpid() && kill(pid, 0) != 0 && errno == ESRCH;
  };
  std::istringstream ns(run_cmd({ip_binary(), "netns", "list"}).output);
  for (std::string line; std::getline(ns, line);) {
    std::string name = line.substr(0, line.find(' '));
    if (stale_pid(name)) ip({"netns", "del", name});
  }
  std::istringstream links(run_cmd({ip_binary(), "-o", "link", "show"}).output);
  for (std::string line; std::getline(links, line);) {
    // "12: tsr123ah@if11: <...": the name sits between ": " and "@" or ":".
    auto at = line.find(": ");
    if (at == std::string::npos) continue;
    std::string name = line.substr(at + 2, line.find_first_of("@:", at + 2) - at - 2);
    if (stale_pid(name)) ip({"link", "del", name});
  }
}

// One namespace joined to the root namespace by a veth pair; removed by the destructor.
struct Netns {
  std::string name, host_if, ns_if, host_ip, ns_ip;
  bool made = false;

  Netns(char letter, int subnet) {
    const std::string base = "tsr" + std::to_string(getpid()) + letter;
    name = base;
    host_if = base + "h";
    ns_if = base + "n";
    host_ip = "10.213." + std::to_string(subnet) + ".1";
    ns_ip = "10.213." + std::to_string(subnet) + ".2";
  }
  Netns(const Netns&) = delete;
  Netns& operator=(const Netns&) = delete;
  ~Netns() { remove(); }
  void remove() {
    // Deleting the namespace deletes the inner end, and with it the pair; the link is
    // deleted too in case the namespace was never made.
    ip({"netns", "del", name});
    ip({"link", "del", host_if});
  }
  // Empty on success, else why not.
  std::string create() {
    remove();  // leftovers of the same names
    made = true;
    for (auto& cmd : std::vector<std::vector<std::string>>{
             {"netns", "add", name},
             {"link", "add", host_if, "type", "veth", "peer", "name", ns_if, "netns", name},
             {"addr", "add", host_ip + "/24", "dev", host_if},
             {"link", "set", host_if, "up"},
             {"-n", name, "addr", "add", ns_ip + "/24", "dev", ns_if},
             {"-n", name, "link", "set", "lo", "up"},
             {"-n", name, "link", "set", ns_if, "up"},
         })
      if (std::string err = ip(cmd); !err.empty()) return err;
    // `ip netns exec` also needs a mount namespace of its own (CAP_SYS_ADMIN).
    CmdResult r = run_cmd({ip_binary(), "netns", "exec", name, ip_binary(), "-o", "addr", "show", "dev", ns_if});
    if (r.status != 0 || r.output.find(ns_ip + "/") == std::string::npos)
      return "`ip netns exec " + name + "` does not work: " + r.output;
    return {};
  }
  // The link goes down inside the namespace: nothing of the veth pair reaches the other side,
  // yet the root namespace keeps its route (no packets leak to the default route) and the
  // sockets on both sides stay open.
  std::string cut() { return ip({"-n", name, "link", "set", ns_if, "down"}); }
  std::string restore() { return ip({"-n", name, "link", "set", ns_if, "up"}); }
};

// Third octets of the two subnets: from the pid, so that two runs at once do not collide.
int subnet_base() { return 1 + 2 * int(getpid() % 100); }

// Why this machine cannot run the test (empty: it can).
std::string unavailable() {
  if (const char* e = std::getenv("TESSERA_NO_NETNS"); e && *e && std::string(e) != "0")
    return "TESSERA_NO_NETNS=" + std::string(e);
  if (ip_binary().empty()) return "no iproute2 `ip` binary";
  if (geteuid() != 0) return "not root: network namespaces need CAP_NET_ADMIN (run as root)";
  remove_stale();
  Netns probe('p', subnet_base());
  std::string err = probe.create();
  return err.empty() ? err : "cannot build a network namespace: " + err;
}

std::string field(const std::string& line, const std::string& key) {
  auto at = line.find("\"" + key + "\": \"");
  if (at == std::string::npos) return {};
  at += key.size() + 5;
  return line.substr(at, line.find('"', at) - at);
}

std::string last_line_with(const std::string& log, const std::string& needle) {
  auto at = log.rfind(needle);
  if (at == std::string::npos) return {};
  auto begin = log.rfind('\n', at);
  begin = begin == std::string::npos ? 0 : begin + 1;
  auto end = log.find('\n', at);
  return log.substr(begin, end == std::string::npos ? std::string::npos : end - begin);
}

size_t count(const std::string& s, const std::string& needle) {
  size_t n = 0;
  for (auto at = s.find(needle); at != std::string::npos; at = s.find(needle, at + 1)) ++n;
  return n;
}

// One `tessera serve` process (`prefix` runs it in a namespace); its first stdout line names
// its endpoints.
struct Node {
  std::unique_ptr<Process> p;
  uint16_t http = 0;
  std::string cluster;

  Node(std::vector<std::string> prefix, std::vector<std::string> extra) {
    std::vector<std::string> a = std::move(prefix);
    for (std::string s : {TESSERA_BINARY, "serve", "--threads", "1", "--web-root", "web"}) a.push_back(s);
    a.push_back("--tessera.reconnect-ms=" + std::to_string(kReconnectMs));
    a.push_back("--tessera.task-timeout-ms=" + std::to_string(kTaskTimeoutMs));
    a.insert(a.end(), extra.begin(), extra.end());
    p = std::make_unique<Process>(a);
    auto line = p->first_line(30000);
    INFO("stderr: " << p->err());
    REQUIRE(line);
    std::string url = field(*line, "listening");
    if (!url.empty()) http = uint16_t(std::stoi(url.substr(url.rfind(':') + 1)));
    cluster = field(*line, "cluster");
  }
};

// The nodes' mutual TLS (docs/operations.md): off, or certificates that scripts/cluster-certs.sh
// makes into a temporary folder (removed at the end), one per node, with the workers' addresses
// as subjectAltNames.
struct Tls {
  std::string dir;  // "": no TLS
  Tls() = default;
  explicit Tls(const std::vector<std::string>& nodes) {
    char tmpl[] = "/tmp/tessera-netns-tls-XXXXXX";
    REQUIRE(mkdtemp(tmpl) != nullptr);
    dir = tmpl;
    std::vector<std::string> a{"/bin/bash", TESSERA_CERTS_SCRIPT, dir + "/certs"};
    a.insert(a.end(), nodes.begin(), nodes.end());
    CmdResult r = run_cmd(a);
    INFO("scripts/cluster-certs.sh: " << r.output);
    REQUIRE(r.status == 0);
  }
  Tls(const Tls&) = delete;
  Tls& operator=(const Tls&) = delete;
  ~Tls() {
    if (!dir.empty()) run_cmd({"/bin/rm", "-rf", dir});
  }
  // The settings of node `name` ({} without TLS).
  std::vector<std::string> args(const std::string& name) const {
    if (dir.empty()) return {};
    return {"--tessera.cluster-tls-cert=" + dir + "/certs/" + name + ".pem",
            "--tessera.cluster-tls-key=" + dir + "/certs/" + name + ".key",
            "--tessera.cluster-tls-ca=" + dir + "/certs/ca.pem"};
  }
};

// A worker inside a namespace, its cluster port bound to the namespace's address.
Node worker(const Netns& ns, const std::string& name, const Tls& tls) {
  std::vector<std::string> a{"--no-http", "--cluster-port", std::to_string(kClusterPort),
                             "--tessera.cluster-host=" + ns.ns_ip, "--tessera.name=" + name};
  for (auto& t : tls.args(name)) a.push_back(t);
  return Node({ip_binary(), "netns", "exec", ns.name}, a);
}


// The master's cluster_frame line of client frame `number`.
std::string cluster_frame(Process& master, uint32_t number) {
  return last_line_with(master.err(), "\"cluster_frame\": " + std::to_string(number) + ",");
}

}  // namespace

namespace {

// Two workers in their namespaces and a dedicated master: frames right before, during and after
// a cut of one worker's link, over plain CAF or over mutual TLS (`tls`).
void cut_link_and_rejoin(const Tls& tls) {
  Netns a('a', subnet_base()), b('b', subnet_base() + 1);
  {
    std::string err = a.create();
    INFO(err);
    REQUIRE(err.empty());
    err = b.create();
    INFO(err);
    REQUIRE(err.empty());
  }
  const std::string addr_a = a.ns_ip + ":" + std::to_string(kClusterPort);
  const std::string addr_b = b.ns_ip + ":" + std::to_string(kClusterPort);
  Node wa = worker(a, "wa", tls), wb = worker(b, "wb", tls);
  CHECK(wa.cluster == addr_a);
  CHECK(wb.cluster == addr_b);
  std::vector<std::string> margs{"--port", "0", "--no-render", "--children", addr_a + "," + addr_b};
  for (auto& t : tls.args("master")) margs.push_back(t);
  Node m({}, margs);
  Process& log = *m.p;
  {
    bool connected = wait_for([&] { return log.err_count("\"child_connected\"") == 2; }, 20000);
    INFO("master stderr: " << log.err());
    REQUIRE(connected);
  }
  // Each node says how its links are secured; without TLS the workers, listening on addresses
  // other machines could reach, and the master with such children, warn.
  const std::string security = tls.dir.empty() ? "\"cluster_security\": \"none\"" : "\"cluster_security\": \"mutual_tls\"";
  for (Process* p : {wa.p.get(), wb.p.get(), &log}) {
    INFO("stderr: " << p->err());
    CHECK(p->err_count(security) == 1);
    CHECK(p->err_count("\"warning\": \"no TLS on ") == (tls.dir.empty() ? 1u : 0u));
  }

  ProtoClient c;
  REQUIRE(c.connect(m.http));
  auto hs = c.handshake(DisplayKind::jpeg, W, H, 95);
  REQUIRE(hs);
  CHECK(hs->nodes == 2);  // a dedicated master: the two workers render, the master does not
  CHECK(log.err_count("\"used\": 2") >= 1);
  REQUIRE(c.upload(pavilion().scene));
  uint32_t n = 1;
  for (size_t k : {0, 40, 80}) {
    check_frame(c, k, n, log);
    // Both workers rendered their own task, nothing was recovered by the master.
    std::string line = cluster_frame(log, n);
    INFO("cluster_frame line: " << line);
    CHECK(count(line, "{\"node\": ") == 2);
    CHECK(line.find("\"recovered\": 0,") != std::string::npos);
    ++n;
  }
  CHECK(log.err_count("\"joined\": \"" + addr_a + "\"") == 1);
  CHECK(log.err_count("\"joined\": \"" + addr_b + "\"") == 1);
  CHECK(wa.p->err_count("\"worker_opened\"") == 1);
  CHECK(wb.p->err_count("\"worker_opened\"") == 1);

  // The link of worker a goes down; its process and its TCP connection live on. The next frame
  // waits for the task timeout, then the master renders a's tiles itself; while a is late the
  // master renders its tiles at once; once a has not answered a ping for another timeout it is
  // lost, and the frames after that tile over b alone. Every frame arrives and is right.
  {
    std::string err = a.cut();
    INFO(err);
    REQUIRE(err.empty());
  }
  const std::string lost = "\"node_lost\": \"" + addr_a + "\"";
  const std::string join_failed = "\"join_failed\": \"" + addr_a + "\"";
  std::string took;  // how long each frame took, for the messages
  auto t_lost = std::chrono::steady_clock::now();
  for (size_t k : {100, 110, 120, 130, 140}) {
    auto t0 = std::chrono::steady_clock::now();
    check_frame(c, k, n, log);
    took += std::to_string(n) + ": " +
            std::to_string(std::chrono::duration_cast<std::chrono::milliseconds>(std::chrono::steady_clock::now() - t0).count()) +
            " ms; ";
    ++n;
    if (k == 120) {  // a is late; it is lost a timeout after its deadline
      INFO("master stderr: " << tail(log.err()));
      REQUIRE(wait_for([&] { return log.err_count(lost) == 1; }, 3 * kTaskTimeoutMs));
      t_lost = std::chrono::steady_clock::now();
    }
  }
  {
    INFO("master stderr: " << tail(log.err()));
    INFO("frames: " << took);
    CHECK(log.err_count("\"node_late\": \"" + addr_a + "\"") == 1);
    // While a is cut off, the session retries it (an open that waits for the task timeout)
    // every reconnect period; the frames after the first must not wait for those attempts.
    // They did: each waited for one failed join, about the task timeout per frame, so the
    // four frames after the first saw four. Now the retries fail once per timeout + reconnect
    // period from node_lost on, whatever the frames do: at most one in flight, so no more than
    // one per 3.2 s since node_lost, plus the one in flight (the frames take about 0.3 s each,
    // 0.5 s on a loaded machine, but several seconds each under ASan on a loaded one).
    const auto since_lost_ms =
        std::chrono::duration_cast<std::chrono::milliseconds>(std::chrono::steady_clock::now() - t_lost).count();
    INFO(since_lost_ms << " ms since node_lost was seen");
    CHECK(log.err_count(join_failed) <= size_t(2 + since_lost_ms / (kTaskTimeoutMs + kReconnectMs)));
    std::string line = last_line_with(log.err(), lost);
    INFO("node_lost line: " << line);
    REQUIRE(!line.empty());
    CHECK(line.find("timeout") != std::string::npos);  // noticed by the timeout, not a closed connection
    CHECK(log.err_count("\"recovering\"") >= 1);
    CHECK(log.err_count("\"used\": 1") >= 1);  // the next frame tiled over b alone
    CHECK(log.err_count("\"child_lost\"") == 0);
    CHECK(log.err_count(lost) == 1);
    CHECK(log.err_count("\"node_lost\": \"" + addr_b + "\"") == 0);
  }
  CHECK(wa.p->wait(0) == std::nullopt);  // still running

  // The link comes back: the connection resumes (TCP retransmits after its back-off), the
  // session opens a worker on a again, and frames tile over both workers.
  {
    std::string err = a.restore();
    INFO(err);
    REQUIRE(err.empty());
  }
  {
    bool rejoined = wait_for([&] { return log.err_count("\"joined\": \"" + addr_a + "\"") == 2; }, 20000);
    INFO("master stderr: " << tail(log.err(), 8000));
    INFO("worker a stderr: " << tail(wa.p->err()));
    REQUIRE(rejoined);
  }
  const size_t used2 = log.err_count("\"used\": 2");
  for (size_t k : {140, 160}) {
    check_frame(c, k, n, log);
    ++n;
  }
  {
    std::string line = cluster_frame(log, n - 1);
    INFO("master stderr: " << tail(log.err()));
    INFO("worker a stderr: " << tail(wa.p->err()));
    INFO("cluster_frame line: " << line);
    CHECK(log.err_count("\"used\": 2") == used2 + 1);
    CHECK(count(line, "{\"node\": ") == 2);
    CHECK(line.find("\"recovered\": 0,") != std::string::npos);
    CHECK(log.err_count(lost) == 1);
  }
  CHECK(log.err_count("\"error\"") == 0);  // the client never got an error

  // Opens that the cut link held reach a when it comes back; those the master had given up on
  // by then (whether there are any depends on when the retries ran) open orphans, which end
  // by themselves: no adoption notice within twice the master's timeout ("orphaned"), or no
  // keep-alive for keepalive-misses periods ("parent silent"), whichever comes first. The
  // first worker ended when the cut stopped its keep-alives or the master stopped it. Only the
  // rejoined worker lives on. (tests/actor/test_cluster_actors.cpp checks each rule
  // deterministically.)
  {
    const size_t opened = wa.p->err_count("\"worker_opened\"");
    INFO("worker a stderr: " << tail(wa.p->err()));
    CHECK(opened >= 2);
    CHECK(wait_for([&] { return wa.p->err_count("\"worker_closed\"") + 1 == opened; }, 2 * kTaskTimeoutMs + 5000));
    CHECK(wa.p->err_count("\"worker_opened\"") == opened);
    CHECK(wb.p->err_count("\"orphaned\"") == 0);
  }
}

}  // namespace

TEST_CASE("Workers in two network namespaces render for a master; a cut link times out, is covered and rejoins",
          "[cluster][fault][netns]") {
  cut_link_and_rejoin(Tls());
}

TEST_CASE("Over mutual TLS workers in two network namespaces survive a cut link and rejoin",
          "[cluster][fault][netns][tls]") {
  // The workers' certificates name their addresses (10.213.K.2; CAF does not check them).
  const int k = subnet_base();
  cut_link_and_rejoin(Tls({"master", "wa=10.213." + std::to_string(k) + ".2", "wb=10.213." + std::to_string(k + 1) + ".2"}));
}

int test_prelude() {
  if (std::string why = unavailable(); !why.empty()) {
    std::printf("test_cluster_netns: skipped: %s\n", why.c_str());
    return 77;
  }
  return 0;
}
