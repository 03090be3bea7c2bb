#include "core/static_path.h"

#include <filesystem>

namespace tessera {

namespace fs = std::filesystem;

std::string target_path(const std::string& target) {
  return target.substr(0, target.find_first_of("?#"));
}

namespace {

int hex(char c) {
  if (c >= '0' && c <= '9') return c - '0';
  if (c >= 'a' && c <= 'f') return c - 'a' + 10;
  if (c >= 'A' && c <= 'F') return c - 'A' + 10;
  return -1;
}

std::optional<std::string> percent_decode(const std::string& s) {
  std::string out;
  for (size_t i = 0; i < s.size(); ++i) {
    if (s[i] != '%') { out += s[i]; continue; }
    if (i + 2 >= s.size()) return std::nullopt;
    int a = hex(s[i + 1]), b = hex(s[i + 2]);
    if (a < 0 || b < 0) return std::nullopt;
    char c = char(a * 16 + b);
    if (c == '\0') return std::nullopt;
    out += c;
    i += 2;
  }
  return out;
}

}  // namespace

std::optional<std::string> resolve_static(const std::string& root, const std::string& target) {
  if (target.empty() || target[0] != '/') return std::nullopt;
  auto decoded = percent_decode(target_path(target));
  if (!decoded) return std::nullopt;
  std::string rel;
  size_t i = 1;
  const std::string& p = *decoded;
  while (i <= p.size()) {
    size_t j = p.find('/', i);
    if (j == std::string::npos) j = p.size();
    std::string seg = p.substr(i, j - i);
    if (!seg.empty()) {
      if (seg[0] == '.' || seg.find('\\') != std::string::npos) return std::nullopt;  // "..", ".", hidden
      if (!rel.empty()) rel += '/';
      rel += seg;
    }
    i = j + 1;
  }
  if (p.back() == '/') rel += rel.empty() ? "index.html" : "/index.html";
  std::error_code ec;
  fs::path base = fs::weakly_canonical(fs::path(root), ec);
  if (ec) return std::nullopt;
  fs::path full = fs::weakly_canonical(base / rel, ec);
  if (ec) return std::nullopt;
  if (fs::is_directory(full, ec)) full /= "index.html";
  // Must stay inside root after resolving symlinks.
  auto b = base.string(), f = full.string();
  if (f.size() <= b.size() || f.compare(0, b.size(), b) != 0 || f[b.size()] != '/') return std::nullopt;
  if (!fs::is_regular_file(full, ec)) return std::nullopt;
  return f;
}

}  // namespace tessera
