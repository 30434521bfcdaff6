#pragma once
// The built web viewer as static files: maps a request target to a file
// under the web root, or to an error. No I/O beyond stat and canonicalisation;
// the HTTP server sends the file.

#include <filesystem>
#include <optional>
#include <string>
#include <string_view>

namespace filigree::server::http {

class StaticFiles {
 public:
  // `root` empty: nothing is served (every request gets a 404 that says so).
  explicit StaticFiles(std::optional<std::filesystem::path> root);

  struct Result {
    unsigned status = 404;            // 200, 400 or 404
    std::filesystem::path file;       // status 200: the file to send
    std::string content_type;         // status 200: its media type
    std::string message;              // otherwise: a short plain-text explanation
  };
  // `target` is the request target ("/", "/assets/app.js?v=1"): the query is
  // ignored, the path percent-decoded; "/" and directories mean index.html.
  // Any ".." segment (also percent-encoded), a NUL or a backslash is 400; a
  // path that leaves the root (also through a symlink) or names no regular
  // file is 404.
  Result resolve(std::string_view target) const;

  const std::optional<std::filesystem::path>& root() const { return root_; }

  // The media type for a file name's extension (application/octet-stream when unknown).
  static std::string_view content_type(const std::filesystem::path& file);

 private:
  std::optional<std::filesystem::path> root_;  // canonical
};

}  // namespace filigree::server::http
