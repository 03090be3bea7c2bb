// `tessera <command> [options]`: render, bench, balance, serve, ...
#include <cstdio>
#include <cstring>
#include <map>
#include <string>
#include <vector>

#include "app/command.h"

namespace tessera::app {
namespace {
struct Entry {
  const char* summary;
  CommandFn fn;
};
std::map<std::string, Entry>& registry() {
  static std::map<std::string, Entry> r;
  return r;
}
}  // namespace

Command::Command(const char* name, const char* summary, CommandFn fn) {
  registry()[name] = Entry{summary, fn};
}

}  // namespace tessera::app

int main(int argc, char** argv) {
  using namespace tessera::app;
  auto usage = [] {
    std::fprintf(stderr, "usage: tessera <command> [options]\n\ncommands:\n");
    for (auto& [name, e] : registry()) std::fprintf(stderr, "  %-10s %s\n", name.c_str(), e.summary);
    std::fprintf(stderr, "\n`tessera <command> --help` describes a command's options.\n");
  };
  if (argc < 2 || !std::strcmp(argv[1], "--help") || !std::strcmp(argv[1], "-h")) {
    usage();
    return argc < 2 ? 2 : 0;
  }
  auto it = registry().find(argv[1]);
  if (it == registry().end()) {
    std::fprintf(stderr, "tessera: unknown command '%s'\n", argv[1]);
    usage();
    return 2;
  }
  std::vector<std::string> args(argv + 2, argv + argc);
  try {
    return it->second.fn(args);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "tessera %s: %s\n", argv[1], e.what());
    return 1;
  }
}
