#include "server/http/static_files.h"

#include <algorithm>
#include <array>
#include <cctype>
#include <utility>

#include "server/http/hex_value.h"

namespace filigree::server::http {
namespace {

// Percent-decodes a URL path; nullopt on a malformed escape.
std::optional<std::string> percent_decode(std::string_view in) {
  std::string out;
  out.reserve(in.size());
  for (std::size_t i = 0; i < in.size(); ++i) {
    if (in[i] != '%') {
      out += in[i];
      continue;
    }
    if (i + 2 >= in.size()) return std::nullopt;
    const int hi = hex_value(in[i + 1]), lo = hex_value(in[i + 2]);
    if (hi < 0 || lo < 0) return std::nullopt;
    out += static_cast<char>(hi * 16 + lo);
    i += 2;
  }
  return out;
}

bool is_within(const std::filesystem::path& root, const std::filesystem::path& p) {
  const auto [r, q] = std::mismatch(root.begin(), root.end(), p.begin(), p.end());
  return r == root.end();
}

StaticFiles::Result error(unsigned status, std::string message) {
  StaticFiles::Result r;
  r.status = status;
  r.message = std::move(message);
  return r;
}

}  // namespace

StaticFiles::StaticFiles(std::optional<std::filesystem::path> root) {
  if (root) root_ = std::filesystem::canonical(*root);
}

std::string_view StaticFiles::content_type(const std::filesystem::path& file) {
  static constexpr std::array<std::pair<std::string_view, std::string_view>, 17> kTypes{{
      {".html", "text/html; charset=utf-8"},
      {".htm", "text/html; charset=utf-8"},
      {".js", "text/javascript; charset=utf-8"},
      {".mjs", "text/javascript; charset=utf-8"},
      {".css", "text/css; charset=utf-8"},
      {".wasm", "application/wasm"},
      {".json", "application/json"},
      {".map", "application/json"},
      {".png", "image/png"},
      {".svg", "image/svg+xml"},
      {".jpg", "image/jpeg"},
      {".jpeg", "image/jpeg"},
      {".ico", "image/x-icon"},
      {".txt", "text/plain; charset=utf-8"},
      {".glb", "model/gltf-binary"},
      {".gltf", "model/gltf+json"},
      {".webp", "image/webp"},
  }};
  std::string ext = file.extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  for (const auto& [e, type] : kTypes)
    if (e == ext) return type;
  return "application/octet-stream";
}

StaticFiles::Result StaticFiles::resolve(std::string_view target) const {
  if (!root_)
    return error(404,
                 "filigree-server: no web viewer is served here (no --web-root given, and no built viewer next to "
                 "the executable). gRPC-Web is answered on this port at /filigree.v1.Filigree/<Method>.\n");
  const std::string_view path = target.substr(0, target.find_first_of("?#"));
  if (path.empty() || path.front() != '/') return error(400, "bad request target\n");
  const std::optional<std::string> decoded = percent_decode(path);
  if (!decoded) return error(400, "bad percent-encoding in the path\n");
  if (decoded->find('\0') != std::string::npos || decoded->find('\\') != std::string::npos)
    return error(400, "bad characters in the path\n");

  // Split into segments; refuse any "..", skip "" and ".".
  std::filesystem::path relative;
  std::size_t at = 1;
  while (at <= decoded->size()) {
    const std::size_t end = std::min(decoded->find('/', at), decoded->size());
    const std::string_view segment = std::string_view(*decoded).substr(at, end - at);
    if (segment == "..") return error(400, "'..' is not allowed in paths\n");
    if (!segment.empty() && segment != ".") relative /= std::string(segment);
    at = end + 1;
  }

  std::filesystem::path candidate = *root_ / relative;
  std::error_code ec;
  if (std::filesystem::is_directory(candidate, ec)) candidate /= "index.html";
  const std::filesystem::path resolved = std::filesystem::canonical(candidate, ec);
  if (ec || !is_within(*root_, resolved) || !std::filesystem::is_regular_file(resolved, ec))
    return error(404, "not found\n");
  Result r;
  r.status = 200;
  r.file = resolved;
  r.content_type = std::string(content_type(resolved));
  return r;
}

}  // namespace filigree::server::http
