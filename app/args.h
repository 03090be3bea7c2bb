#pragma once
// A small command-line reader for the subcommands: --name value [value...] and flags.
#include <cstdlib>
#include <stdexcept>
#include <string>
#include <vector>

namespace tessera::app {

class Args {
 public:
  explicit Args(const std::vector<std::string>& a) : a_(a), used_(a.size(), false) {}

  bool flag(const std::string& name) {
    for (size_t i = 0; i < a_.size(); ++i)
      if (a_[i] == name) { used_[i] = true; return true; }
    return false;
  }
  // The k-th value after --name, or fallback when --name is absent.
  std::string str(const std::string& name, const std::string& fallback = "", int k = 0) {
    for (size_t i = 0; i < a_.size(); ++i)
      if (a_[i] == name) {
        used_[i] = true;
        if (i + 1 + k >= a_.size()) throw std::invalid_argument(name + " needs a value");
        used_[i + 1 + k] = true;
        return a_[i + 1 + k];
      }
    return fallback;
  }
  std::string required(const std::string& name) {
    std::string v = str(name, "\x01");
    if (v == "\x01") throw std::invalid_argument("missing required option " + name);
    return v;
  }
  long integer(const std::string& name, long fallback, int k = 0) {
    std::string v = str(name, "", k);
    if (v.empty()) return fallback;
    char* end = nullptr;
    long r = std::strtol(v.c_str(), &end, 10);
    if (!end || *end) throw std::invalid_argument(name + ": '" + v + "' is not an integer");
    return r;
  }
  double number(const std::string& name, double fallback) {
    std::string v = str(name, "");
    if (v.empty()) return fallback;
    char* end = nullptr;
    double r = std::strtod(v.c_str(), &end);
    if (!end || *end) throw std::invalid_argument(name + ": '" + v + "' is not a number");
    return r;
  }
  // Throws on options nobody asked for (typos should not pass silently).
  void finish() const {
    for (size_t i = 0; i < a_.size(); ++i)
      if (!used_[i]) throw std::invalid_argument("unknown option or stray value '" + a_[i] + "'");
  }

 private:
  std::vector<std::string> a_;
  std::vector<bool> used_;
};

}  // namespace tessera::app
