#include "server/api_keys.h"

#include <fstream>
#include <sstream>
#include <stdexcept>

#include <openssl/crypto.h>
#include <openssl/sha.h>

namespace filigree::server {
namespace {

std::array<std::uint8_t, 32> sha256(std::string_view bytes) {
  std::array<std::uint8_t, 32> out{};
  SHA256(reinterpret_cast<const unsigned char*>(bytes.data()), bytes.size(), out.data());
  return out;
}

int hex_digit(char c) {
  if (c >= '0' && c <= '9') return c - '0';
  if (c >= 'a' && c <= 'f') return c - 'a' + 10;
  if (c >= 'A' && c <= 'F') return c - 'A' + 10;
  return -1;
}

}  // namespace

ApiKeys ApiKeys::parse(std::string_view text, const std::string& file) {
  ApiKeys keys;
  std::istringstream lines{std::string(text)};
  std::string line;
  for (int number = 1; std::getline(lines, line); ++number) {
    const auto fail = [&](const std::string& why) {
      throw std::runtime_error(file + ":" + std::to_string(number) + ": " + why);
    };
    if (const auto hash = line.find('#'); hash != std::string::npos) line.resize(hash);
    std::istringstream words(line);
    ApiKey key;
    std::string hex;
    if (!(words >> key.name)) continue;  // blank or comment
    if (!(words >> hex) || hex.size() != 64) fail("expected NAME and the key's SHA-256 in 64 hex digits");
    for (std::size_t i = 0; i < 32; ++i) {
      const int hi = hex_digit(hex[2 * i]), lo = hex_digit(hex[2 * i + 1]);
      if (hi < 0 || lo < 0) fail("the key's SHA-256 is not hexadecimal");
      key.hash[i] = static_cast<std::uint8_t>(hi * 16 + lo);
    }
    for (std::string quota; words >> quota;) {
      const auto eq = quota.find('=');
      std::uint64_t value = 0;
      try {
        std::size_t used = 0;
        if (eq == std::string::npos) throw std::invalid_argument("no '='");
        value = std::stoull(quota.substr(eq + 1), &used);
        if (used != quota.size() - eq - 1) throw std::invalid_argument("trailing characters");
      } catch (const std::exception&) {
        fail("quota '" + quota + "' is not NAME=NUMBER");
      }
      const std::string what = quota.substr(0, eq);
      if (what == "sessions") key.quota.sessions = value;
      else if (what == "vertices") key.quota.vertices = value;
      else if (what == "uploads_per_minute") key.quota.uploads_per_minute = value;
      else if (what == "streams") key.quota.streams = value;
      else fail("unknown quota '" + what + "' (sessions, vertices, uploads_per_minute, streams)");
    }
    if (keys.by_name(key.name)) fail("key name '" + key.name + "' is used twice");
    keys.keys_.push_back(std::move(key));
  }
  return keys;
}

ApiKeys ApiKeys::load(const std::string& path) {
  std::ifstream in(path);
  if (!in) throw std::runtime_error("API keys file " + path + " cannot be read");
  std::ostringstream text;
  text << in.rdbuf();
  return parse(text.str(), path);
}

const ApiKey* ApiKeys::find(std::string_view presented) const {
  if (presented.empty()) return nullptr;
  const std::array<std::uint8_t, 32> hash = sha256(presented);
  const ApiKey* found = nullptr;
  for (const ApiKey& key : keys_)  // every key, whichever matches
    if (CRYPTO_memcmp(hash.data(), key.hash.data(), hash.size()) == 0) found = &key;
  return found;
}

const ApiKey* ApiKeys::by_name(std::string_view name) const {
  for (const ApiKey& key : keys_)
    if (key.name == name) return &key;
  return nullptr;
}

}  // namespace filigree::server
