// libFuzzer target: what a node does with the bytes of an HTTP request before it answers.
// websocketpp's request parser (http::parser::request::consume, in two pieces split where the
// first byte says) and, for a complete request, the node's routing helpers (net/http.h):
// target_path, query_param, valid_token and resolve_static over a scratch web root that holds
// a file outside the root, a symlink to it, a hidden directory and a directory without an
// index; and the redirect port's Location (redirect_host of the Host header, location).
// Invariants: resolve_static returns only regular files inside the root (after resolving
// symlinks), never the file outside it, nothing hidden; valid_token accepts only 8..64 of
// [A-Za-z0-9_-]; a Location is https://HOST:PORT/ of URL characters only (no space, quote, angle
// bracket, backslash or control byte) and HOST only a name or an address.
#include <cctype>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <optional>
#include <string>

#include <websocketpp/http/request.hpp>
#include <websocketpp/processors/processor.hpp>

#include "net/http.h"
#include "tests/fuzz/fuzz_common.h"

using namespace tessera;
namespace fs = std::filesystem;

namespace {

struct Roots {
  std::string web, scenes, secret;
};

void put(const fs::path& p, const std::string& text) {
  fs::create_directories(p.parent_path());
  std::ofstream(p) << text;
}

const Roots& roots() {
  static const Roots r = [] {
    fs::path base = fuzz::scratch_dir();
    Roots x;
    x.web = fs::canonical(base).string() + "/www";
    x.scenes = fs::canonical(base).string() + "/scenes";
    x.secret = fs::canonical(base).string() + "/secret.txt";
    put(x.secret, "secret\n");
    put(x.web + "/index.html", "<html></html>\n");
    put(x.web + "/app.js", "1;\n");
    put(x.web + "/demo/index.html", "<html></html>\n");
    put(x.web + "/demo/a b.css", "a{}\n");
    put(x.web + "/.git/config", "hidden\n");
    put(x.web + "/empty/readme.txt", "no index here\n");
    put(x.scenes + "/room/scene.gltf", "{}\n");
    fs::create_symlink(x.secret, x.web + "/link.txt");
    fs::create_directory_symlink(base, x.web + "/up");
    return x;
  }();
  return r;
}

void check_resolved(const std::string& root, const std::string& target, const std::optional<std::string>& file) {
  if (!file) return;
  std::error_code ec;
  fs::path real = fs::canonical(*file, ec);
  bool inside = !ec && real.string().rfind(root + "/", 0) == 0;
  bool regular = !ec && fs::is_regular_file(real);
  bool hidden = real.string().find("/.", root.size()) != std::string::npos;
  if (!inside || !regular || hidden || real.string() == roots().secret) {
    std::fprintf(stderr, "resolve_static(%s, \"%s\") gave %s\n", root.c_str(), target.c_str(), file->c_str());
    std::abort();
  }
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  if (size == 0) return 0;
  const Roots& r = roots();
  size_t split = size > 1 ? 1 + data[0] % (size - 1) : 1;
  const char* bytes = reinterpret_cast<const char*>(data);
  websocketpp::http::parser::request req;
  try {
    size_t used = req.consume(bytes + 1, split - 1);
    if (!req.ready() && used == split - 1) req.consume(bytes + split, size - split);
  } catch (const websocketpp::http::exception&) {
    return 0;  // answered with the exception's status (400, 413, ...)
  }
  if (!req.ready()) return 0;

  // What Server::Impl::on_http / on_validate read from a complete request.
  (void)req.get_method();
  (void)req.get_version();
  (void)req.get_header("Host");
  (void)websocketpp::processor::is_websocket_handshake(req);
  (void)websocketpp::processor::get_websocket_version(req);
  websocketpp::http::parameter_list extensions;
  (void)req.get_header_as_plist("Sec-WebSocket-Extensions", extensions);

  const std::string& target = req.get_uri();
  std::string path = http::target_path(target);
  std::string token = http::query_param(target, "session");
  for (const std::string& t : {token, path.rfind("/mjpeg/", 0) == 0 ? path.substr(7) : std::string()}) {
    if (!http::valid_token(t)) continue;
    bool ok = t.size() >= 8 && t.size() <= 64;
    for (unsigned char c : t) ok &= std::isalnum(c) || c == '_' || c == '-';
    if (!ok) {
      std::fprintf(stderr, "valid_token accepted \"%s\"\n", t.c_str());
      std::abort();
    }
  }
  check_resolved(r.web, target, http::resolve_static(r.web, target));
  if (target.rfind("/scenes/", 0) == 0) check_resolved(r.scenes, target, http::resolve_static(r.scenes, target.substr(7)));
  (void)http::mime_type(path);

  // What the redirect port answers (Server's on_redirect_http): 127.0.0.1 stands for the node's
  // address when the Host header is not taken.
  const std::string host = http::redirect_host(req.get_header("Host")).value_or("127.0.0.1");
  const std::string location = http::location("https", host, 8443, target);
  bool ok = location.rfind("https://" + host + ":8443/", 0) == 0;
  for (unsigned char c : location) ok &= c > 0x20 && c < 0x7f && c != '"' && c != '<' && c != '>' && c != '\\';
  for (unsigned char c : host) ok &= std::isalnum(c) || c == '-' || c == '.' || c == '[' || c == ']' || c == ':';
  if (!ok) {
    std::fprintf(stderr, "redirect for Host \"%s\" and \"%s\": \"%s\"\n", req.get_header("Host").c_str(), target.c_str(),
                 location.c_str());
    std::abort();
  }
  return 0;
}
