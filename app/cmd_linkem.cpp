// tessera linkem --ns A B --addr IP_A IP_B [--mbit R] [--rtt-ms T] [--loss-percent P]
//                [--queue-kb Q] [--mtu M] [--dev NAME] [--seed S] [--open-until-signal]
// An emulated network link between two Linux network namespaces, for kernels without sch_netem
// (this project's VMs: "Specified qdisc kind is unknown"). It makes a TUN device in each
// namespace, gives them point-to-point addresses (A's device IP_A with peer IP_B, B's the other
// way round), and forwards every IP packet from one to the other through net/link_model.h: a
// drop-tail queue in front of a link of R Mbit/s, then half the round-trip time of delay, and
// random loss, in each direction (as `tc qdisc ... netem delay T/2 loss P rate R limit ...` on
// both ends of a veth pair would). The packets are not changed, so TCP between the namespaces
// sees a real link: its round trips, its losses (and retransmits them), its rate.
//
// Prints one JSON line {"linkem": "ready", ...} once both devices are up, and on SIGINT or SIGTERM
// one line of counters per direction. --open-until-signal: the link has its delay but no rate
// limit and no loss until SIGUSR1, then shapes as asked: a bench uploads its scene, then
// measures frames on the shaped link (loadtest --on-streaming). The delay is there from the
// start because TCP keeps the least round-trip time it has seen (BBR's model of the link is
// built on it): a link that was 0 ms and then 50 ms would fool it for seconds. Needs CAP_NET_ADMIN and CAP_SYS_ADMIN (setns) and
// /dev/net/tun. Used by bench/display_network.sh and tests/e2e/test_linkem.cpp.
#include <arpa/inet.h>
#include <fcntl.h>
#include <linux/if.h>
#include <linux/if_tun.h>
#include <netinet/in.h>
#include <poll.h>
#include <sched.h>
#include <signal.h>
#include <sys/ioctl.h>
#include <sys/prctl.h>
#include <sys/socket.h>
#include <time.h>
#include <unistd.h>

#include <cerrno>
#include <cstdio>
#include <cstring>
#include <deque>
#include <stdexcept>
#include <string>
#include <vector>

#include "app/args.h"
#include "app/command.h"
#include "net/link_model.h"

namespace tessera::app {
namespace {

const char* kHelp =
    "tessera linkem --ns A B --addr IP_A IP_B [--mbit R] [--rtt-ms T] [--loss-percent P]\n"
    "               [--queue-kb Q] [--mtu M] [--dev NAME] [--seed S] [--open-until-signal]\n"
    "An emulated link between network namespaces A and B (names under /run/netns, as `ip netns add`\n"
    "makes them, or paths), for kernels without sch_netem: a TUN device NAME (default tlk0) in each,\n"
    "addressed IP_A and IP_B (IPv4, point to point), and every packet between them forwarded through\n"
    "a drop-tail queue of Q KiB (default: 200 ms of the rate, at least 64) in front of a link of\n"
    "R Mbit/s (default 0: no limit), then T/2 ms of delay (default 0), and lost with probability P%\n"
    "(default 0), in each direction. MTU M (default 1500). --seed S: the loss draws (default 1).\n"
    "Prints {\"linkem\": \"ready\", ...} once the devices are up; runs until SIGINT or SIGTERM, then\n"
    "prints each direction's counters (of the shaped link). --open-until-signal: the delay but no rate limit\n"
    "and no loss until SIGUSR1 (then {\"linkem\": \"shaped\"}). Needs root (CAP_NET_ADMIN, CAP_SYS_ADMIN) and\n"
    "/dev/net/tun.\n";

volatile sig_atomic_t g_stop = 0, g_shape = 0;
void on_signal(int) { g_stop = 1; }
void on_usr1(int) { g_shape = 1; }

[[noreturn]] void fail(const std::string& what) {
  throw std::runtime_error(what + ": " + std::strerror(errno));
}

int64_t now_ns() {
  timespec ts;
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return int64_t(ts.tv_sec) * 1'000'000'000 + ts.tv_nsec;
}

std::string netns_path(const std::string& name) {
  if (name.find('/') != std::string::npos) return name;
  for (const char* dir : {"/run/netns/", "/var/run/netns/"})
    if (access((dir + name).c_str(), F_OK) == 0) return dir + name;
  throw std::invalid_argument("no network namespace '" + name + "' (ip netns add " + name + ")");
}

in_addr parse_ipv4(const std::string& s) {
  in_addr a{};
  if (inet_pton(AF_INET, s.c_str(), &a) != 1) throw std::invalid_argument("'" + s + "' is not an IPv4 address");
  return a;
}

void set_addr(ifreq& ifr, in_addr a) {
  auto* sin = reinterpret_cast<sockaddr_in*>(&ifr.ifr_addr);
  std::memset(sin, 0, sizeof *sin);
  sin->sin_family = AF_INET;
  sin->sin_addr = a;
}

// Enters the namespace at `path` (this thread), makes TUN device `dev` there, addresses it
// (`self`, peer `peer`), sets its MTU and brings it up. Returns the device's non-blocking fd.
int make_tun(const std::string& path, const std::string& dev, in_addr self, in_addr peer, int mtu) {
  const int ns = open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (ns < 0) fail("open " + path);
  if (setns(ns, CLONE_NEWNET) != 0) fail("setns " + path);
  close(ns);
  const int fd = open("/dev/net/tun", O_RDWR | O_NONBLOCK | O_CLOEXEC);
  if (fd < 0) fail("open /dev/net/tun");
  ifreq ifr{};
  ifr.ifr_flags = IFF_TUN | IFF_NO_PI;
  std::snprintf(ifr.ifr_name, IFNAMSIZ, "%s", dev.c_str());
  if (ioctl(fd, TUNSETIFF, &ifr) != 0) fail("TUNSETIFF " + dev + " in " + path);
  const int s = socket(AF_INET, SOCK_DGRAM | SOCK_CLOEXEC, 0);  // in this namespace
  if (s < 0) fail("socket");
  set_addr(ifr, self);
  if (ioctl(s, SIOCSIFADDR, &ifr) != 0) fail("SIOCSIFADDR " + dev);
  set_addr(ifr, peer);
  if (ioctl(s, SIOCSIFDSTADDR, &ifr) != 0) fail("SIOCSIFDSTADDR " + dev);
  set_addr(ifr, in_addr{htonl(0xffffffffu)});
  if (ioctl(s, SIOCSIFNETMASK, &ifr) != 0) fail("SIOCSIFNETMASK " + dev);
  ifr.ifr_mtu = mtu;
  if (ioctl(s, SIOCSIFMTU, &ifr) != 0) fail("SIOCSIFMTU " + dev);
  if (ioctl(s, SIOCGIFFLAGS, &ifr) != 0) fail("SIOCGIFFLAGS " + dev);
  ifr.ifr_flags = short(ifr.ifr_flags | IFF_UP | IFF_RUNNING);
  if (ioctl(s, SIOCSIFFLAGS, &ifr) != 0) fail("SIOCSIFFLAGS " + dev);
  close(s);
  return fd;
}

struct Packet {
  int64_t arrive_ns;
  std::vector<unsigned char> bytes;
};

// One direction: packets read from `in`, kept until they arrive, written to `out`.
struct Direction {
  const char* name;
  int in, out;
  LinkDirection link;
  std::deque<Packet> flight;  // in arrival order (net/link_model.h)
  size_t flight_bytes = 0;
  uint64_t over_cap = 0, write_errors = 0;
};

// Bytes a direction holds at most (queued and in flight), whatever the link: a link without a
// rate limit has no queue, and its delay line holds what comes in during the delay.
constexpr size_t kMaxFlightBytes = 256u << 20;

void read_all(Direction& d, std::vector<unsigned char>& buf) {
  for (int i = 0; i < 256; ++i) {  // then let the other direction have its turn
    const ssize_t n = read(d.in, buf.data(), buf.size());
    if (n < 0) {
      if (errno == EAGAIN || errno == EINTR) return;
      fail(std::string("read ") + d.name);
    }
    if (n == 0) return;
    const int64_t t = d.link.admit(now_ns(), size_t(n));
    if (t == LinkDirection::kDropped) continue;
    if (d.flight_bytes + size_t(n) > kMaxFlightBytes) {
      ++d.over_cap;
      continue;
    }
    d.flight.push_back(Packet{t, std::vector<unsigned char>(buf.begin(), buf.begin() + n)});
    d.flight_bytes += size_t(n);
  }
}

void deliver(Direction& d, int64_t now) {
  while (!d.flight.empty() && d.flight.front().arrive_ns <= now) {
    auto& p = d.flight.front();
    if (write(d.out, p.bytes.data(), p.bytes.size()) != ssize_t(p.bytes.size())) ++d.write_errors;
    d.flight_bytes -= p.bytes.size();
    d.flight.pop_front();
  }
}

int run(const std::vector<std::string>& argv) {
  Args args(argv);
  if (args.flag("--help")) {
    std::fputs(kHelp, stdout);
    return 0;
  }
  const std::string ns_a = args.required("--ns"), ns_b = args.str("--ns", "", 1);
  const std::string ip_a = args.required("--addr"), ip_b = args.str("--addr", "", 1);
  LinkParams p;
  p.mbit_s = args.number("--mbit", 0);
  p.delay_ms = args.number("--rtt-ms", 0) / 2;
  p.loss = args.number("--loss-percent", 0) / 100;
  const double queue_kb = args.number("--queue-kb", 0);
  const long mtu = args.integer("--mtu", 1500);
  const std::string dev = args.str("--dev", "tlk0");
  p.seed = uint64_t(args.integer("--seed", 1));
  const bool open_first = args.flag("--open-until-signal");
  args.finish();
  p.validate();
  if (!(queue_kb >= 0 && queue_kb <= 1 << 20)) throw std::invalid_argument("--queue-kb must be 0..1048576");
  p.queue_bytes = size_t(queue_kb * 1024);
  if (mtu < 576 || mtu > 65535) throw std::invalid_argument("--mtu must be 576..65535");
  if (dev.empty() || dev.size() >= IFNAMSIZ) throw std::invalid_argument("--dev must be 1..15 characters");
  const in_addr a = parse_ipv4(ip_a), b = parse_ipv4(ip_b);

  // SIGINT, SIGTERM and SIGUSR1 are blocked except inside ppoll, so none is missed between the
  // check and the wait.
  struct sigaction sa {};
  sa.sa_handler = on_signal;
  sigaction(SIGINT, &sa, nullptr);
  sigaction(SIGTERM, &sa, nullptr);
  sa.sa_handler = on_usr1;
  sigaction(SIGUSR1, &sa, nullptr);
  sigset_t ours, wait_mask;
  sigemptyset(&ours);
  for (int sig : {SIGINT, SIGTERM, SIGUSR1}) sigaddset(&ours, sig);
  sigprocmask(SIG_BLOCK, &ours, &wait_mask);
  for (int sig : {SIGINT, SIGTERM, SIGUSR1}) sigdelset(&wait_mask, sig);

  const int home = open("/proc/self/ns/net", O_RDONLY | O_CLOEXEC);
  const int fa = make_tun(netns_path(ns_a), dev, a, b, int(mtu));
  const int fb = make_tun(netns_path(ns_b), dev, b, a, int(mtu));
  if (home >= 0) {
    setns(home, CLONE_NEWNET);
    close(home);
  }
  prctl(PR_SET_TIMERSLACK, 1UL);  // wake-ups to the microsecond: a full packet at 100 Mbit/s is 120 us

  LinkParams pb = p;
  pb.seed = p.seed * 0x9E3779B97F4A7C15ull + 1;  // the other direction's own loss draws
  LinkParams open;
  open.delay_ms = p.delay_ms;
  Direction dirs[2] = {{"a_to_b", fa, fb, LinkDirection(open_first ? open : p), {}, 0, 0, 0},
                       {"b_to_a", fb, fa, LinkDirection(open_first ? open : pb), {}, 0, 0, 0}};
  if (!open_first) g_shape = 0;
  std::printf("{\"linkem\": \"ready\", \"ns\": [\"%s\", \"%s\"], \"addr\": [\"%s\", \"%s\"], \"dev\": \"%s\", "
              "\"mbit_s\": %g, \"rtt_ms\": %g, \"loss_percent\": %g, \"queue_bytes\": %zu, \"mtu\": %ld}\n",
              ns_a.c_str(), ns_b.c_str(), ip_a.c_str(), ip_b.c_str(), dev.c_str(), p.mbit_s, p.delay_ms * 2,
              p.loss * 100, dirs[0].link.queue_bytes(), mtu);
  std::fflush(stdout);

  std::vector<unsigned char> buf(size_t(mtu) + 64);
  bool shaped = !open_first;
  while (!g_stop) {
    if (g_shape && !shaped) {  // packets already in flight arrive as the open link said
      shaped = true;
      dirs[0].link = LinkDirection(p);
      dirs[1].link = LinkDirection(pb);
      std::printf("{\"linkem\": \"shaped\"}\n");
      std::fflush(stdout);
    }
    int64_t next = -1;
    for (auto& d : dirs)
      if (!d.flight.empty() && (next < 0 || d.flight.front().arrive_ns < next)) next = d.flight.front().arrive_ns;
    timespec ts{}, *timeout = nullptr;
    if (next >= 0) {
      const int64_t wait = std::max<int64_t>(0, next - now_ns());
      ts.tv_sec = time_t(wait / 1'000'000'000);
      ts.tv_nsec = long(wait % 1'000'000'000);
      timeout = &ts;
    }
    pollfd fds[2] = {{fa, POLLIN, 0}, {fb, POLLIN, 0}};
    const int r = ppoll(fds, 2, timeout, &wait_mask);
    if (r < 0 && errno != EINTR) fail("ppoll");
    if (r > 0) {
      for (int i = 0; i < 2; ++i)
        if (fds[i].revents & (POLLERR | POLLHUP | POLLNVAL)) throw std::runtime_error("a TUN device went away");
      for (int i = 0; i < 2; ++i)
        if (fds[i].revents & POLLIN) read_all(dirs[i], buf);
    }
    const int64_t t = now_ns();
    for (auto& d : dirs) deliver(d, t);
  }
  for (auto& d : dirs)
    std::printf("{\"linkem\": \"counters\", \"direction\": \"%s\", \"packets\": %llu, \"lost\": %llu, \"queue_full\": %llu, "
                "\"over_cap\": %llu, \"forwarded\": %llu, \"bytes\": %llu, \"write_errors\": %llu}\n",
                d.name, (unsigned long long)d.link.packets(), (unsigned long long)d.link.lost(),
                (unsigned long long)d.link.full(), (unsigned long long)d.over_cap,
                (unsigned long long)d.link.forwarded(), (unsigned long long)d.link.bytes(),
                (unsigned long long)d.write_errors);
  std::fflush(stdout);
  close(fa);
  close(fb);
  return 0;
}

const Command reg("linkem", "an emulated network link (rate, delay, loss) between two network namespaces", run);

}  // namespace
}  // namespace tessera::app
