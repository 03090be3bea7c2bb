#pragma once
// Child processes for the e2e and cluster tests.
#include <fcntl.h>
#include <signal.h>
#include <stdlib.h>
#include <sys/wait.h>
#include <unistd.h>

#include <catch2/catch.hpp>

#include <chrono>
#include <optional>
#include <string>
#include <thread>
#include <vector>

namespace tessera::test {

// A child process (tessera serve) whose stdout and stderr go to temporary files, so a
// chatty node never blocks on a full pipe while the test is busy elsewhere.
class Process {
 public:
  explicit Process(const std::vector<std::string>& args) {
    char out_name[] = "/tmp/tessera-test-out-XXXXXX", err_name[] = "/tmp/tessera-test-err-XXXXXX";
    const int out_w = mkstemp(out_name), err_w = mkstemp(err_name);
    REQUIRE(out_w >= 0);
    REQUIRE(err_w >= 0);
    out_ = open(out_name, O_RDONLY);
    err_ = open(err_name, O_RDONLY);
    unlink(out_name);
    unlink(err_name);
    pid_ = fork();
    REQUIRE(pid_ >= 0);
    if (pid_ == 0) {
      dup2(out_w, 1);
      dup2(err_w, 2);
      close(out_w), close(err_w);
      std::vector<char*> argv;
      for (auto& a : args) argv.push_back(const_cast<char*>(a.c_str()));
      argv.push_back(nullptr);
      execv(argv[0], argv.data());
      _exit(127);
    }
    close(out_w);
    close(err_w);
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
      std::this_thread::sleep_for(std::chrono::milliseconds(20));
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
  pid_t pid() const { return pid_; }
  const std::string& out() { pump(); return stdout_; }
  const std::string& err() { pump(); return stderr_; }
  // How often `needle` occurs in stderr so far.
  size_t err_count(const std::string& needle) {
    pump();
    size_t n = 0;
    for (size_t at = stderr_.find(needle); at != std::string::npos; at = stderr_.find(needle, at + 1)) ++n;
    return n;
  }

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

}  // namespace tessera::test
