#pragma once
// What of a request may go into a log line. The web viewer's address carries
// the session's token (/?session=…&token=…), and browsers may send API keys:
// a log line shows neither, whatever the log level.

#include <cstddef>
#include <string>
#include <string_view>

namespace filigree::server::http {

// Longest request target a log line shows; the rest is cut (with "…").
inline constexpr std::size_t kLoggedTargetBytes = 512;

// `target` (path and query) for a log line: the value of every query
// parameter whose name (percent-decoded, any case) says it is a secret —
// it contains "token", "key", "secret", "passw", "auth" or "sig" — is
// replaced by "REDACTED"; cut to kLoggedTargetBytes.
std::string redacted_target(std::string_view target);

// Whether a request header carries a secret and must never be logged
// (lower-case name): x-filigree-token, x-filigree-api-key, authorization,
// cookie, and any name as redacted_target judges parameter names.
bool is_secret_header(std::string_view lower_name);

}  // namespace filigree::server::http
