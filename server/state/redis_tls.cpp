#include "server/state/redis_tls.h"

#include <openssl/err.h>
#include <openssl/ssl.h>

#include "server/state/session_store.h"

namespace filigree::server {

std::string openssl_reason(unsigned long e) {
  if (e == 0) return "unknown OpenSSL error";
  if (const char* reason = ERR_reason_error_string(e)) return reason;
  char buf[256];
  ERR_error_string_n(e, buf, sizeof buf);
  return buf;
}

namespace {

// The reason of OpenSSL's oldest queued error ("no such file", "key values
// mismatch"), the queue then cleared.
std::string queued_openssl_reason() {
  const unsigned long e = ERR_get_error();
  ERR_clear_error();
  return openssl_reason(e);
}

// An encrypted key would make OpenSSL prompt on the terminal of a server
// that has none: refuse it instead (the load then fails and says so).
int no_passphrase(char*, int, int, void*) { return 0; }

}  // namespace

RedisTls::RedisTls(const RedisTlsOptions& options) : options_(options) {
  if (options_.cert_file.empty() != options_.key_file.empty())
    throw StoreUnavailable("Redis TLS: a client certificate needs both its certificate file and its key file");
  ERR_clear_error();
  ctx_ = SSL_CTX_new(TLS_client_method());
  if (!ctx_) throw StoreUnavailable("Redis TLS: cannot create an OpenSSL context: " + queued_openssl_reason());
  try {
    // Redis 7 speaks TLS 1.2 and 1.3; nothing older is safe.
    SSL_CTX_set_min_proto_version(ctx_, TLS1_2_VERSION);
    SSL_CTX_set_default_passwd_cb(ctx_, no_passphrase);
    SSL_CTX_set_verify(ctx_, SSL_VERIFY_PEER, nullptr);
    if (options_.ca_file.empty()) {
      if (SSL_CTX_set_default_verify_paths(ctx_) != 1)
        throw StoreUnavailable("Redis TLS: cannot load the system CA store: " + queued_openssl_reason());
    } else if (SSL_CTX_load_verify_locations(ctx_, options_.ca_file.c_str(), nullptr) != 1) {
      throw StoreUnavailable("Redis TLS: cannot load the CA file " + options_.ca_file + ": " + queued_openssl_reason());
    }
    if (!options_.cert_file.empty()) {
      if (SSL_CTX_use_certificate_chain_file(ctx_, options_.cert_file.c_str()) != 1)
        throw StoreUnavailable("Redis TLS: cannot load the client certificate " + options_.cert_file + ": " +
                               queued_openssl_reason());
      if (SSL_CTX_use_PrivateKey_file(ctx_, options_.key_file.c_str(), SSL_FILETYPE_PEM) != 1)
        throw StoreUnavailable("Redis TLS: cannot load the client key " + options_.key_file + ": " + queued_openssl_reason());
      if (SSL_CTX_check_private_key(ctx_) != 1)
        throw StoreUnavailable("Redis TLS: the client key " + options_.key_file + " does not match the certificate " +
                               options_.cert_file);
    }
  } catch (...) {
    SSL_CTX_free(ctx_);
    throw;
  }
}

RedisTls::~RedisTls() { SSL_CTX_free(ctx_); }

std::string RedisTls::trust() const {
  return options_.ca_file.empty() ? "the system CA store" : "CA file " + options_.ca_file;
}

}  // namespace filigree::server
