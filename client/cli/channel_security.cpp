#include "cli/channel_security.h"

#include <cctype>
#include <cstdlib>
#include <fstream>
#include <sstream>
#include <stdexcept>
#include <string>

#include <CLI/CLI.hpp>
#include <grpcpp/security/credentials.h>

namespace filigree::cli {
namespace {

struct Options {
  bool tls = false;
  std::string ca, cert, key, api_key_file;
};
Options options;  // one tool invocation, one connection policy

std::string read_pem(const std::string& path, const char* what) {
  std::ifstream in(path);
  if (!in) throw std::runtime_error(std::string(what) + " " + path + " cannot be read");
  std::ostringstream text;
  text << in.rdbuf();
  return text.str();
}

}  // namespace

void add_channel_security_options(CLI::App& app) {
  app.add_flag("--tls", options.tls, "Reach the server over TLS, trusting the system's CAs");
  app.add_option("--tls-ca", options.ca, "CA bundle (PEM) that signed the server's certificate (implies --tls)");
  app.add_option("--tls-cert", options.cert, "Client certificate (PEM) for a server that wants mutual TLS");
  app.add_option("--tls-key", options.key, "Its private key (PEM)");
  app.add_option("--api-key-file", options.api_key_file,
                 "File whose first line is the API key upload and sessions present (default: $FILIGREE_API_KEY)");
  app.fallthrough();  // subcommands pass these up: `filigree watch --tls-ca ca.pem …` works
}

std::string api_key() {
  std::string key;
  if (!options.api_key_file.empty()) {
    std::istringstream first(read_pem(options.api_key_file, "--api-key-file"));
    std::getline(first, key);
  } else if (const char* env = std::getenv("FILIGREE_API_KEY")) {
    key = env;
  }
  while (!key.empty() && std::isspace(static_cast<unsigned char>(key.back()))) key.pop_back();
  return key;
}

std::shared_ptr<grpc::ChannelCredentials> channel_credentials() {
  if (options.cert.empty() != options.key.empty()) throw std::runtime_error("--tls-cert and --tls-key go together");
  if (!options.tls && options.ca.empty() && options.cert.empty()) return grpc::InsecureChannelCredentials();
  grpc::SslCredentialsOptions ssl;
  if (!options.ca.empty()) ssl.pem_root_certs = read_pem(options.ca, "--tls-ca");
  if (!options.cert.empty()) {
    ssl.pem_cert_chain = read_pem(options.cert, "--tls-cert");
    ssl.pem_private_key = read_pem(options.key, "--tls-key");
  }
  return grpc::SslCredentials(ssl);
}

}  // namespace filigree::cli
