#pragma once
// HTTPS on the browser port: the OpenSSL server context built from the same
// PEM files as the gRPC port (--tls-cert, --tls-key, --tls-client-ca), and
// renewed when they are replaced. A connection keeps the context it was
// accepted with, so a renewal never drops an open connection.

#include <chrono>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

namespace boost::asio::ssl {
class context;
}

namespace filigree::server::http {

struct HttpsFiles {
  std::string cert;  // certificate chain (PEM); empty: plaintext HTTP
  std::string key;   // its private key (PEM)
  // CA bundle (PEM); non-empty: mutual TLS, as on the gRPC port. Otherwise
  // --http would be a way around --tls-client-ca to the same service.
  std::string client_ca;
  // How often a new connection may look at the files' modification times
  // (the gRPC port polls every 5 s); zero: at every new connection.
  std::chrono::seconds refresh{5};
  bool enabled() const { return !cert.empty(); }
};

// A server context from `files`. Throws std::runtime_error naming the option
// and the file when one cannot be read, holds no usable PEM, or the key does
// not belong to the certificate.
std::shared_ptr<boost::asio::ssl::context> make_https_context(const HttpsFiles& files);

// The context new connections use, renewed from the files. Thread-safe.
class HttpsContextSource {
 public:
  // Builds the first context; throws as make_https_context.
  explicit HttpsContextSource(HttpsFiles files);
  ~HttpsContextSource();

  // The current context. At most every `refresh`, first checks the files and
  // rebuilds the context if one of them changed; a failed rebuild is logged
  // and the previous context stays (a renewal half written is retried when
  // the files change again).
  std::shared_ptr<boost::asio::ssl::context> current();

  // Rebuilds from the files now. Throws std::runtime_error (as
  // make_https_context) and keeps the previous context if they are bad.
  void reload();

  const HttpsFiles& files() const { return files_; }

  // What identifies a file's version: device, inode, size, modification time.
  struct Stamp {
    long long dev = -1, ino = -1, size = -1, mtime_ns = -1;
    bool operator==(const Stamp&) const = default;
  };

 private:
  std::vector<Stamp> stamps() const;
  void replace(std::shared_ptr<boost::asio::ssl::context> context, const char* why);

  const HttpsFiles files_;
  std::mutex mutex_;
  std::shared_ptr<boost::asio::ssl::context> context_;
  std::vector<Stamp> stamps_;  // of the files the last build (good or bad) read
  std::chrono::steady_clock::time_point last_check_;
};

}  // namespace filigree::server::http
