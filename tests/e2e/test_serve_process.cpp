// End to end with `tessera serve` as a separate process (the built binary, TESSERA_BINARY):
// it starts on a free port (--port 0, the port read from its "listening" line), serves a
// client that uploads a scene and gets a frame, serves the static page and a 404, and exits
// with status 0 on SIGTERM within a bounded time, with a client still connected. A config
// file that does not exist, a bad setting and a port in use each end it with a clear error
// and a non-zero status.
#include <catch2/catch.hpp>

#include <fcntl.h>
#include <poll.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cstring>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include "net/http.h"
#include "tests/e2e/node_fixture.h"

using namespace tessera;
using namespace tessera::test;

namespace {

// A child process with its stdout and stderr on pipes.
class Process {
 public:
  explicit Process(const std::vector<std::string>& args) {
    int out[2], err[2];
    REQUIRE(pipe(out) == 0);
    REQUIRE(pipe(err) == 0);
    pid_ = fork();
    REQUIRE(pid_ >= 0);
    if (pid_ == 0) {
      dup2(out[1], 1);
      dup2(err[1], 2);
      close(out[0]), close(out[1]), close(err[0]), close(err[1]);
      std::vector<char*> argv;
      for (auto& a : args) argv.push_back(const_cast<char*>(a.c_str()));
      argv.push_back(nullptr);
      execv(argv[0], argv.data());
      _exit(127);
    }
    close(out[1]);
    close(err[1]);
    out_ = out[0];
    err_ = err[0];
    fcntl(out_, F_SETFL, O_NONBLOCK);
    fcntl(err_, F_SETFL, O_NONBLOCK);
  }
  ~Process() {
    if (pid_ > 0 && !status_) {
      kill(pid_, SIGKILL);
      waitpid(pid_, nullptr, 0);
    }
    close(out_);
    close(err_);
  }
  // The first line the child writes to stdout, within timeout_ms.
  std::optional<std::string> first_line(int timeout_ms) {
    auto deadline = std::chrono::steady_clock::now() + std::chrono::milliseconds(timeout_ms);
    while (std::chrono::steady_clock::now() < deadline) {
      pump();
      auto nl = stdout_.find('\n');
      if (nl != std::string::npos) return stdout_.substr(0, nl);
      if (exited(0)) return std::nullopt;
      pollfd p{out_, POLLIN, 0};
      poll(&p, 1, 50);
    }
    return std::nullopt;
  }
  // Waits up to timeout_ms for the child to exit; its wait status, or nullopt.
  std::optional<int> wait(int timeout_ms) {
    auto deadline = std::chrono::steady_clock::now() + std::chrono::milliseconds(timeout_ms);
    do {
      pump();
      if (exited(0)) break;
      std::this_thread::sleep_for(std::chrono::milliseconds(20));
    } while (std::chrono::steady_clock::now() < deadline);
    pump();
    return status_;
  }
  void signal(int sig) { kill(pid_, sig); }
  const std::string& out() const { return stdout_; }
  const std::string& err() const { return stderr_; }

 private:
  bool exited(int) {
    if (status_) return true;
    int st = 0;
    if (waitpid(pid_, &st, WNOHANG) == pid_) status_ = st;
    return bool(status_);
  }
  void pump() {
    char buf[4096];
    ssize_t n;
    while ((n = read(out_, buf, sizeof buf)) > 0) stdout_.append(buf, size_t(n));
    while ((n = read(err_, buf, sizeof buf)) > 0) stderr_.append(buf, size_t(n));
  }
  pid_t pid_ = -1;
  int out_ = -1, err_ = -1;
  std::string stdout_, stderr_;
  std::optional<int> status_;
};

// The port from serve's first line: {"listening": "http://127.0.0.1:PORT/", ...}.
uint16_t listening_port(const std::string& line) {
  const std::string key = "\"listening\": \"http://127.0.0.1:";
  auto at = line.find(key);
  REQUIRE(at != std::string::npos);
  return uint16_t(std::stoi(line.substr(at + key.size())));
}

std::vector<std::string> serve(std::vector<std::string> extra) {
  std::vector<std::string> a{TESSERA_BINARY, "serve", "--host", "127.0.0.1", "--threads", "2"};
  a.insert(a.end(), extra.begin(), extra.end());
  return a;
}

}  // namespace

TEST_CASE("tessera serve as a process serves a client and the pages, and exits 0 on SIGTERM", "[e2e]") {
  Process p(serve({"--port", "0"}));
  auto line = p.first_line(30000);
  INFO("stderr: " << p.err());
  REQUIRE(line);
  const uint16_t port = listening_port(*line);
  REQUIRE(port != 0);

  ProtoClient c;
  REQUIRE(c.connect(port));
  auto hs = c.handshake(protocol::DisplayKind::jpeg, 96, 64, 85);
  REQUIRE(hs);
  CHECK(hs->width == 96);
  REQUIRE(c.upload(pavilion().scene));
  auto f = c.render(pavilion_loop().camera(0), 7);
  REQUIRE(f);
  CHECK(f->frame == 7);
  CHECK(f->width == 96);
  CHECK(f->height == 64);
  CHECK(f->payload.size() > 100);

  auto page = http::get("127.0.0.1", port, "/");
  REQUIRE(page);
  CHECK(page->status == 200);
  CHECK(page->content_type.find("text/html") != std::string::npos);
  CHECK(page->body.find("<html") != std::string::npos);
  auto missing = http::get("127.0.0.1", port, "/no/such/page.html");
  REQUIRE(missing);
  CHECK(missing->status == 404);

  // SIGTERM with the client still connected: the node closes it and exits cleanly.
  const auto t0 = std::chrono::steady_clock::now();
  p.signal(SIGTERM);
  auto status = p.wait(15000);
  REQUIRE(status);
  CHECK(WIFEXITED(*status));
  CHECK(WEXITSTATUS(*status) == 0);
  CHECK(std::chrono::steady_clock::now() - t0 < std::chrono::seconds(15));
  CHECK(p.err().find("\"stopping\": true") != std::string::npos);
  // The connection is gone: nothing more arrives and the client sees it closed.
  CHECK_FALSE(c.ws.receive(2000).has_value());
  CHECK(c.ws.closed());
}

TEST_CASE("tessera serve exits non-zero with a clear error on a missing config, a bad setting or a port in use",
          "[e2e]") {
  {
    Process p(serve({"--config", "/nonexistent/tessera.ini", "--port", "0"}));
    auto status = p.wait(15000);
    REQUIRE(status);
    CHECK(WIFEXITED(*status));
    CHECK(WEXITSTATUS(*status) != 0);
    INFO("stderr: " << p.err());
    CHECK(p.err().find("/nonexistent/tessera.ini") != std::string::npos);
    CHECK(p.out().find("listening") == std::string::npos);
  }
  {
    Process p(serve({"--port", "0", "--tessera.max-clients=lots"}));
    auto status = p.wait(15000);
    REQUIRE(status);
    CHECK(WIFEXITED(*status));
    CHECK(WEXITSTATUS(*status) != 0);
    INFO("stderr: " << p.err());
    CHECK(p.err().find("max-clients") != std::string::npos);
  }
  {
    Process first(serve({"--port", "0"}));
    auto line = first.first_line(30000);
    REQUIRE(line);
    const uint16_t port = listening_port(*line);
    Process second(serve({"--port", std::to_string(port)}));
    auto status = second.wait(15000);
    REQUIRE(status);
    CHECK(WIFEXITED(*status));
    CHECK(WEXITSTATUS(*status) != 0);
    INFO("stderr: " << second.err());
    CHECK(second.err().find(std::to_string(port)) != std::string::npos);
    CHECK(second.out().find("listening") == std::string::npos);
    // The first node is unaffected and still stops cleanly.
    auto page = http::get("127.0.0.1", port, "/");
    REQUIRE(page);
    CHECK(page->status == 200);
    first.signal(SIGTERM);
    auto st = first.wait(15000);
    REQUIRE(st);
    CHECK(WIFEXITED(*st));
    CHECK(WEXITSTATUS(*st) == 0);
  }
}
