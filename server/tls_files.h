#pragma once
// The gRPC port's transport security: plaintext, TLS, or mutual TLS, from PEM
// files that are re-read while the server runs (replacing them renews the
// certificate without a restart or a dropped session). Files are checked
// before they are put in force (verified_tls_files.h): a bad version keeps
// the good one.

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

class VerifiedTlsFiles;

// The credentials for ServerBuilder::AddListeningPort: plaintext without
// files; else TLS from `verified` (made from the same files, and kept alive
// as long as the server), whose checked copies gRPC re-reads. Throws
// std::runtime_error when cert and key are not given together, or a CA
// option is given without them.
std::shared_ptr<grpc::ServerCredentials> server_credentials(const TlsFiles& files, const VerifiedTlsFiles* verified);

// The credentials with which this replica calls another (the gRPC-Web
// bridge's forwarding, replica_router.h), which serves as this one does:
// plaintext for a plaintext replica; else TLS, verifying the other replica's
// certificate against peer_ca (or the system store) and its advertised host
// name, and, when replicas demand client certificates (client_ca), presenting
// this replica's own certificate, which then needs clientAuth among its
// extended key usages. The checked copies of `verified` are re-read as for
// the server (it must outlive the channels).
std::shared_ptr<grpc::ChannelCredentials> peer_credentials(const TlsFiles& files, const VerifiedTlsFiles* verified);

}  // namespace filigree::server
