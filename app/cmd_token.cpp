// tessera token --key FILE --ttl SECONDS [--subject S]: prints one signed access token
// (net/admission.h, docs/protocol.md "Access tokens") for a node whose tessera.token-key is FILE.
#include <cstdio>
#include <ctime>

#include "app/args.h"
#include "app/command.h"
#include "net/admission.h"

namespace tessera::app {
namespace {

const char* kHelp =
    "tessera token --key FILE --ttl SECONDS [--subject S]\n"
    "Prints an access token signed with the key in FILE (HMAC-SHA256), valid for SECONDS\n"
    "(1..31536000) from now, for the nodes whose tessera.token-key is the same key. --subject names\n"
    "whom it is for (up to 256 bytes; written to the node's log on a refusal, the token never is).\n"
    "A web back-end can make the same tokens itself: docs/protocol.md, \"Access tokens\".\n";

constexpr long kMaxTtl = 365L * 24 * 3600;

int run(const std::vector<std::string>& argv) {
  Args args(argv);
  if (args.flag("--help")) { std::fputs(kHelp, stdout); return 0; }
  const std::string key_file = args.required("--key");
  const long ttl = args.integer("--ttl", -1);
  const std::string subject = args.str("--subject");
  args.finish();
  if (ttl < 1 || ttl > kMaxTtl) throw std::invalid_argument("--ttl must be 1.." + std::to_string(kMaxTtl) + " seconds");
  const std::string key = admission::read_key_file(key_file);
  std::printf("%s\n", admission::make_token(key, int64_t(std::time(nullptr)) + ttl, subject).c_str());
  return 0;
}

const Command reg("token", "print a signed access token for nodes with tessera.token-key", run);

}  // namespace
}  // namespace tessera::app
