// `filigree api-key NAME`: a new API key for filigree-server --api-keys. The
// key is printed once, for the person who will use it; the server's file
// keeps only its SHA-256.

#include <sys/random.h>

#include <cstdint>
#include <cstdio>
#include <memory>
#include <stdexcept>
#include <string>

#include <CLI/CLI.hpp>
#include <openssl/sha.h>

#include "cli/commands.h"

namespace filigree::cli {
namespace {

struct ApiKeyArgs {
  std::string name;
  std::uint64_t sessions = 0, vertices = 0, uploads_per_minute = 0, streams = 0;
};

std::string hex(const unsigned char* bytes, std::size_t n) {
  static constexpr char kHex[] = "0123456789abcdef";
  std::string out;
  for (std::size_t i = 0; i < n; ++i) {
    out += kHex[bytes[i] >> 4];
    out += kHex[bytes[i] & 15];
  }
  return out;
}

void make_key(const ApiKeyArgs& a) {
  for (char c : a.name)
    if (c == ' ' || c == '\t' || c == '#') throw std::runtime_error("a key name has no spaces or '#'");
  unsigned char random[24];
  if (::getrandom(random, sizeof random, 0) != static_cast<ssize_t>(sizeof random))
    throw std::runtime_error("the OS gave no random bytes");
  const std::string key = "fgk_" + hex(random, sizeof random);
  unsigned char digest[SHA256_DIGEST_LENGTH];
  SHA256(reinterpret_cast<const unsigned char*>(key.data()), key.size(), digest);
  std::string line = a.name + " " + hex(digest, sizeof digest);
  const auto quota = [&](const char* what, std::uint64_t v) {
    if (v != 0) line += std::string(" ") + what + "=" + std::to_string(v);
  };
  quota("sessions", a.sessions);
  quota("vertices", a.vertices);
  quota("uploads_per_minute", a.uploads_per_minute);
  quota("streams", a.streams);
  std::printf("key: %s\nline: %s\n", key.c_str(), line.c_str());
  std::fprintf(stderr, "Give the key to its user (FILIGREE_API_KEY or --api-key-file); append the line to the "
                       "server's --api-keys file and send the server SIGHUP. The key is not shown again.\n");
}

}  // namespace

void add_api_key_command(CLI::App& app) {
  auto a = std::make_shared<ApiKeyArgs>();
  CLI::App* cmd = app.add_subcommand("api-key", "Make an API key for filigree-server --api-keys (prints it once)");
  cmd->add_option("name", a->name, "Who the key is for (a word)")->required();
  cmd->add_option("--sessions", a->sessions, "Sessions it may hold at once (0: unlimited)");
  cmd->add_option("--vertices", a->vertices, "Vertices its sessions may hold in all (0: unlimited)");
  cmd->add_option("--uploads-per-minute", a->uploads_per_minute, "Uploads in any minute (0: unlimited)");
  cmd->add_option("--streams", a->streams, "Streams open at once on its sessions (0: unlimited)");
  cmd->callback([a] { make_key(*a); });
}

}  // namespace filigree::cli
