#pragma once
// TLS to Redis: what the operator configures, and the OpenSSL context built
// from it once and shared by every connection of a RedisClient. The server's
// certificate and name are always verified: a Redis that cannot prove who it
// is gets neither the password nor the sessions.

#include <string>

struct ssl_ctx_st;

namespace filigree::server {

// The reason of OpenSSL error `e` ("no such file", "certificate required");
// "unknown OpenSSL error" for 0.
std::string openssl_reason(unsigned long e);

struct RedisTlsOptions {
  bool enabled = false;
  std::string ca_file;      // CA bundle (PEM) Redis' certificate must chain to; empty: the system store
  std::string cert_file;    // client certificate chain (PEM), for Redis' tls-auth-clients; empty: none
  std::string key_file;     // its private key (PEM, unencrypted)
  std::string server_name;  // SNI and the name verified in the certificate; empty: the host of the address
};

class RedisTls {
 public:
  // Loads the CA and client certificate files. Throws StoreUnavailable naming
  // the file that cannot be used (never its contents).
  explicit RedisTls(const RedisTlsOptions& options);
  ~RedisTls();
  RedisTls(const RedisTls&) = delete;
  RedisTls& operator=(const RedisTls&) = delete;

  ssl_ctx_st* context() const { return ctx_; }
  // The client certificate file; empty: none.
  const std::string& client_cert() const { return options_.cert_file; }
  // Where trust comes from, for error messages: "CA file X" or "the system CA store".
  std::string trust() const;
  // The name to verify for a connection to `host`.
  const std::string& server_name(const std::string& host) const {
    return options_.server_name.empty() ? host : options_.server_name;
  }

 private:
  RedisTlsOptions options_;
  ssl_ctx_st* ctx_ = nullptr;
};

}  // namespace filigree::server
