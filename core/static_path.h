#pragma once
// Request targets to files under a folder, without path traversal: the node's static files
// (net/http.h) and the scene files a client references (update/asset_store.h).
#include <optional>
#include <string>

namespace tessera {

// The path of a target without query string and fragment.
std::string target_path(const std::string& target);

// Maps a request target ("/a/b.js?x=1") to a regular file under root. Rejects (nullopt):
// targets not starting with '/', bad or NUL percent-encodings, "..", backslashes, hidden
// segments (".git"), anything resolving outside root (symlinks included), and directories
// without index.html. A target ending in '/' means its index.html.
std::optional<std::string> resolve_static(const std::string& root, const std::string& target);

}  // namespace tessera
