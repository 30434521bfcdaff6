#pragma once
// The gRPC port's transport security: plaintext, TLS, or mutual TLS, from PEM
// files that are re-read while the server runs (replacing them renews the
// certificate without a restart or a dropped session).

#include <memory>
#include <string>

namespace grpc {
class ChannelCredentials;
class ServerCredentials;
}

namespace filigree::server {

struct TlsFiles {
  std::string cert;       // the server's certificate chain (PEM); empty: plaintext
  std::string key;        // its private key (PEM)
  std::string client_ca;  // CA bundle of accepted client certificates; non-empty: mutual TLS
  std::string peer_ca;    // CA bundle other replicas' certificates chain to; empty: the system store
  unsigned refresh_seconds = 5;  // how often the files are checked for changes
  bool enabled() const { return !cert.empty(); }
};

// The credentials for ServerBuilder::AddListeningPort. Throws
// std::runtime_error naming the file and what is wrong when cert and key are
// not given together or a file cannot be read or holds no PEM block.
std::shared_ptr<grpc::ServerCredentials> server_credentials(const TlsFiles& files);

// The credentials with which this replica calls another (the gRPC-Web
// bridge's forwarding, replica_router.h), which serves as this one does:
// plaintext for a plaintext replica; else TLS, verifying the other replica's
// certificate against peer_ca (or the system store) and its advertised host
// name, and, when replicas demand client certificates (client_ca), presenting
// this replica's own certificate, which then needs clientAuth among its
// extended key usages. Files are re-read as for the server. Throws
// std::runtime_error naming the option when a file cannot be read.
std::shared_ptr<grpc::ChannelCredentials> peer_credentials(const TlsFiles& files);

}  // namespace filigree::server
