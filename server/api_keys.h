#pragma once
// Who may create sessions: API keys and their quotas (--api-keys FILE).
//
// The file holds one key per line, stored hashed:
//   NAME SHA256-OF-THE-KEY-IN-HEX [sessions=N] [vertices=N] [uploads_per_minute=N] [streams=N]
// (`filigree api-key NAME` makes a key and prints its line). '#' starts a
// comment. A quota left out, or 0, is unlimited. Clients present the key
// itself in the `x-filigree-api-key` metadata of CreateSession and
// ListSessions; session tokens are untouched.

#include <array>
#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

namespace filigree::server {

struct ApiKeyQuota {
  std::uint64_t sessions = 0;            // sessions held at once
  std::uint64_t vertices = 0;            // vertices of those sessions' meshes, in all
  std::uint64_t uploads_per_minute = 0;  // CreateSession calls in any 60 s
  std::uint64_t streams = 0;             // Drive/Watch/PlayClip streams open at once on its sessions
};

struct ApiKey {
  std::string name;
  std::array<std::uint8_t, 32> hash{};  // SHA-256 of the key
  ApiKeyQuota quota;
};

class ApiKeys {
 public:
  ApiKeys() = default;
  // Parses a keys file's text; throws std::runtime_error naming `file` and
  // the line for a malformed line or a name used twice.
  static ApiKeys parse(std::string_view text, const std::string& file);
  // Reads and parses the file; throws std::runtime_error if it cannot be read.
  static ApiKeys load(const std::string& path);

  // The key whose hash is the presented key's, or null. Compares against
  // every key in constant time (the time says nothing about which matched).
  const ApiKey* find(std::string_view presented) const;
  const ApiKey* by_name(std::string_view name) const;
  std::size_t size() const { return keys_.size(); }

 private:
  std::vector<ApiKey> keys_;
};

}  // namespace filigree::server
