#include "server/http/log_redaction.h"

#include <algorithm>
#include <cctype>

#include "server/http/hex_value.h"

namespace filigree::server::http {
namespace {

// Percent-decoded ('+' as a space) and lower-cased: "%54oken" is "token" to
// a browser's URLSearchParams, so it is to this check too. A malformed
// escape stays as it is.
std::string normalised_name(std::string_view name) {
  std::string out;
  out.reserve(name.size());
  for (std::size_t i = 0; i < name.size(); ++i) {
    char c = name[i];
    if (c == '%' && i + 2 < name.size()) {
      const int hi = hex_value(name[i + 1]), lo = hex_value(name[i + 2]);
      if (hi >= 0 && lo >= 0) {
        c = static_cast<char>(hi * 16 + lo);
        i += 2;
      }
    } else if (c == '+') {
      c = ' ';
    }
    out += static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  }
  return out;
}

bool names_a_secret(std::string_view lower) {
  for (const std::string_view word : {"token", "key", "secret", "passw", "auth", "sig"})
    if (lower.find(word) != std::string_view::npos) return true;
  return false;
}

}  // namespace

std::string redacted_target(std::string_view target) {
  std::string out;
  const std::size_t query = target.find('?');
  const std::size_t fragment = target.find('#', query == std::string_view::npos ? 0 : query);
  out.append(target.substr(0, std::min(query, fragment)));
  if (query != std::string_view::npos && query < fragment) {
    out += '?';
    const std::string_view params = target.substr(query + 1, fragment == std::string_view::npos ? std::string_view::npos
                                                                                                : fragment - query - 1);
    std::size_t at = 0;
    while (at <= params.size()) {
      const std::size_t end = std::min(params.find('&', at), params.size());
      const std::string_view param = params.substr(at, end - at);
      const std::size_t eq = param.find('=');
      const std::string_view name = param.substr(0, eq);
      if (eq != std::string_view::npos && names_a_secret(normalised_name(name)))
        out.append(name).append("=REDACTED");
      else
        out.append(param);
      if (end < params.size()) out += '&';
      at = end + 1;
    }
  }
  // A fragment never reaches a server from a browser; anything after '#' is dropped from the log.
  if (fragment != std::string_view::npos) out += "#…";
  if (out.size() > kLoggedTargetBytes) {
    out.resize(kLoggedTargetBytes);
    out += "…";
  }
  return out;
}

bool is_secret_header(std::string_view lower_name) {
  return lower_name == "authorization" || lower_name == "cookie" || lower_name == "proxy-authorization" ||
         names_a_secret(lower_name);
}

}  // namespace filigree::server::http
