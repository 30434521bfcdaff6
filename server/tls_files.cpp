#include "server/tls_files.h"

#include <stdexcept>

#include <grpcpp/security/credentials.h>
#include <grpcpp/security/server_credentials.h>
#include <grpcpp/security/tls_certificate_provider.h>
#include <grpcpp/security/tls_credentials_options.h>

#include "server/verified_tls_files.h"

namespace filigree::server {

std::shared_ptr<grpc::ServerCredentials> server_credentials(const TlsFiles& files, const VerifiedTlsFiles* verified) {
  if (files.cert.empty() != files.key.empty())
    throw std::runtime_error("--tls-cert and --tls-key go together");
  if (!files.enabled()) {
    if (!files.client_ca.empty()) throw std::runtime_error("--tls-client-ca needs --tls-cert and --tls-key");
    if (!files.peer_ca.empty()) throw std::runtime_error("--peer-ca needs --tls-cert and --tls-key");
    return grpc::InsecureServerCredentials();
  }
  if (!verified) throw std::logic_error("server_credentials: TLS files given, but not verified");
  // gRPC's watcher reads only the checked copies (the key and chain in one
  // file, read as both): a renewal is picked up within refresh_seconds + 1.
  auto provider = std::make_shared<grpc::experimental::FileWatcherCertificateProvider>(
      verified->identity_path(), verified->identity_path(), verified->client_ca_path(),
      VerifiedTlsFiles::kGrpcReadSeconds);
  grpc::experimental::TlsServerCredentialsOptions options(provider);
  options.watch_identity_key_cert_pairs();
  if (!files.client_ca.empty()) {
    options.watch_root_certs();
    options.set_cert_request_type(GRPC_SSL_REQUEST_AND_REQUIRE_CLIENT_CERTIFICATE_AND_VERIFY);
  } else {
    options.set_cert_request_type(GRPC_SSL_DONT_REQUEST_CLIENT_CERTIFICATE);
  }
  return grpc::experimental::TlsServerCredentials(options);
}

std::shared_ptr<grpc::ChannelCredentials> peer_credentials(const TlsFiles& files, const VerifiedTlsFiles* verified) {
  if (!files.enabled()) return grpc::InsecureChannelCredentials();
  if (!verified) throw std::logic_error("peer_credentials: TLS files given, but not verified");
  const bool identity = !files.client_ca.empty();  // the other replica demands a client certificate
  grpc::experimental::TlsChannelCredentialsOptions options;
  if (identity || !files.peer_ca.empty()) {
    const std::string pair = identity ? verified->identity_path() : std::string();
    options.set_certificate_provider(std::make_shared<grpc::experimental::FileWatcherCertificateProvider>(
        pair, pair, verified->peer_ca_path(), VerifiedTlsFiles::kGrpcReadSeconds));
    if (!files.peer_ca.empty()) options.watch_root_certs();  // else gRPC uses the system store
    if (identity) options.watch_identity_key_cert_pairs();
  }
  return grpc::experimental::TlsCredentials(options);
}

}  // namespace filigree::server
