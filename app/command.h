#pragma once
// Subcommands of the `tessera` executable. Each lives in its own app/cmd_*.cpp and
// registers itself with a static Command object; main() dispatches on argv[1].
#include <string>
#include <vector>

namespace tessera::app {

using CommandFn = int (*)(const std::vector<std::string>& args);  // args exclude argv[0..1]

struct Command {
  Command(const char* name, const char* summary, CommandFn fn);
};

}  // namespace tessera::app
