#include "server/tls_files.h"

#include <stdexcept>

#include <grpcpp/security/credentials.h>
#include <grpcpp/security/server_credentials.h>
#include <grpcpp/security/tls_certificate_provider.h>
#include <grpcpp/security/tls_credentials_options.h>

#include "server/pem_file.h"

namespace filigree::server {

std::shared_ptr<grpc::ServerCredentials> server_credentials(const TlsFiles& files) {
  if (files.cert.empty() != files.key.empty())
    throw std::runtime_error("--tls-cert and --tls-key go together");
  if (!files.enabled()) {
    if (!files.client_ca.empty()) throw std::runtime_error("--tls-client-ca needs --tls-cert and --tls-key");
    if (!files.peer_ca.empty()) throw std::runtime_error("--peer-ca needs --tls-cert and --tls-key");
    return grpc::InsecureServerCredentials();
  }
  // Checked here, so a wrong path fails at start with its name rather than as
  // handshakes that fail later with a generic error.
  read_pem(files.cert, "--tls-cert");
  read_pem(files.key, "--tls-key");
  if (!files.client_ca.empty()) read_pem(files.client_ca, "--tls-client-ca");
  // A file watcher: a renewed certificate is picked up within refresh_seconds.
  auto provider = std::make_shared<grpc::experimental::FileWatcherCertificateProvider>(
      files.key, files.cert, files.client_ca, files.refresh_seconds);
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

std::shared_ptr<grpc::ChannelCredentials> peer_credentials(const TlsFiles& files) {
  if (!files.enabled()) return grpc::InsecureChannelCredentials();
  if (!files.peer_ca.empty()) read_pem(files.peer_ca, "--peer-ca");
  const bool identity = !files.client_ca.empty();  // the other replica demands a client certificate
  grpc::experimental::TlsChannelCredentialsOptions options;
  if (identity || !files.peer_ca.empty()) {
    options.set_certificate_provider(std::make_shared<grpc::experimental::FileWatcherCertificateProvider>(
        identity ? files.key : "", identity ? files.cert : "", files.peer_ca, files.refresh_seconds));
    if (!files.peer_ca.empty()) options.watch_root_certs();  // else gRPC uses the system store
    if (identity) options.watch_identity_key_cert_pairs();
  }
  return grpc::experimental::TlsCredentials(options);
}

}  // namespace filigree::server
