#pragma once
// How the CLI's client commands reach the server: plaintext, or TLS with
// --tls-ca (the server's CA; default: the system's roots when --tls is given)
// and --tls-cert/--tls-key for mutual TLS. Options of the whole tool, so they
// may stand before or after the subcommand.

#include <memory>
#include <string>

namespace CLI {
class App;
}
namespace grpc {
class ChannelCredentials;
}

namespace filigree::cli {

void add_channel_security_options(CLI::App& app);

// The API key for a server started with --api-keys: --api-key-file's first
// line, else $FILIGREE_API_KEY, else empty (never an argument).
std::string api_key();

// The credentials the options ask for. Throws std::runtime_error naming a
// file that cannot be read, or --tls-cert without --tls-key.
std::shared_ptr<grpc::ChannelCredentials> channel_credentials();

}  // namespace filigree::cli
