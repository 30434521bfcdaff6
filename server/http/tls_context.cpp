#include "server/http/tls_context.h"

#include <stdexcept>
#include <utility>

#include <sys/stat.h>

#include <boost/asio/buffer.hpp>
#include <boost/asio/ssl/context.hpp>
#include <boost/asio/ssl/error.hpp>
#include <openssl/crypto.h>
#include <openssl/err.h>
#include <openssl/pem.h>
#include <openssl/ssl.h>
#include <openssl/x509.h>
#include <spdlog/spdlog.h>

#include "server/pem_file.h"
#include "server/tls_pair_check.h"

namespace filigree::server::http {
namespace {

namespace ssl = boost::asio::ssl;

// Every certificate of the bundle is trusted for client certificates and
// named in the CertificateRequest, so that a browser offers only a matching one.
void trust_clients_of(ssl::context& context, const std::string& pem, const std::string& path) {
  BIO* bio = BIO_new_mem_buf(pem.data(), static_cast<int>(pem.size()));
  if (!bio) throw std::runtime_error("out of memory reading --tls-client-ca " + path);
  int count = 0;
  SSL_CTX* ctx = context.native_handle();
  while (X509* cert = PEM_read_bio_X509(bio, nullptr, nullptr, nullptr)) {
    const bool ok =
        X509_STORE_add_cert(SSL_CTX_get_cert_store(ctx), cert) == 1 && SSL_CTX_add_client_CA(ctx, cert) == 1;
    X509_free(cert);
    if (!ok) {
      BIO_free(bio);
      throw std::runtime_error("--tls-client-ca " + path + ": a certificate could not be added (a duplicate?)");
    }
    ++count;
  }
  BIO_free(bio);
  ERR_clear_error();  // the end of the bundle reads as a "no start line" error
  if (count == 0) throw std::runtime_error("--tls-client-ca " + path + " holds no certificate");
  context.set_verify_mode(ssl::verify_peer | ssl::verify_fail_if_no_peer_cert);
  // Session resumption with client certificates needs a session id context.
  static constexpr unsigned char kSessionContext[] = "filigree-https";
  SSL_CTX_set_session_id_context(ctx, kSessionContext, sizeof kSessionContext - 1);
}

std::string subject_of(ssl::context& context) {
  X509* cert = SSL_CTX_get0_certificate(context.native_handle());
  if (!cert) return {};
  char line[512] = {};
  X509_NAME_oneline(X509_get_subject_name(cert), line, sizeof line - 1);
  return line;
}

HttpsContextSource::Stamp stamp_of(const std::string& path) {
  struct stat st {};
  if (path.empty() || ::stat(path.c_str(), &st) != 0) return {};
  return {static_cast<long long>(st.st_dev), static_cast<long long>(st.st_ino), static_cast<long long>(st.st_size),
          static_cast<long long>(st.st_mtim.tv_sec) * 1'000'000'000LL + st.st_mtim.tv_nsec};
}

}  // namespace

std::shared_ptr<ssl::context> make_https_context(const HttpsFiles& files) {
  // The same checks as the gRPC port's (parse, key match, validity, strength,
  // signature digest), so that both ports accept and refuse the same files.
  CheckedTlsPair pair = read_checked_tls_pair(files.cert, files.key);
  const std::string client_ca = files.client_ca.empty() ? std::string() : read_pem(files.client_ca, "--tls-client-ca");

  auto context = std::make_shared<ssl::context>(ssl::context::tls_server);
  context->set_options(ssl::context::default_workarounds | ssl::context::no_sslv2 | ssl::context::no_sslv3 |
                       ssl::context::single_dh_use);
  // TLS 1.0 and 1.1 are deprecated (RFC 8996); every browser speaks 1.2 and 1.3.
  SSL_CTX_set_min_proto_version(context->native_handle(), TLS1_2_VERSION);
  boost::system::error_code ec;
  context->use_certificate_chain(boost::asio::buffer(pair.chain_pem), ec);
  if (ec) throw std::runtime_error("--tls-cert " + files.cert + " is not a usable certificate chain: " + ec.message());
  context->use_private_key(boost::asio::buffer(pair.key_pem), ssl::context::pem, ec);
  if (ec) throw std::runtime_error("--tls-key " + files.key + " is not a usable private key: " + ec.message());
  if (SSL_CTX_check_private_key(context->native_handle()) != 1) {
    ERR_clear_error();
    throw std::runtime_error("--tls-key " + files.key + " is not the key of the certificate in --tls-cert " +
                             files.cert);
  }
  if (!client_ca.empty()) trust_clients_of(*context, client_ca, files.client_ca);
  return context;
}

HttpsContextSource::HttpsContextSource(HttpsFiles files) : files_(std::move(files)) {
  stamps_ = stamps();
  replace(make_https_context(files_), "start");
  last_check_ = std::chrono::steady_clock::now();
}

HttpsContextSource::~HttpsContextSource() = default;

std::vector<HttpsContextSource::Stamp> HttpsContextSource::stamps() const {
  return {stamp_of(files_.cert), stamp_of(files_.key), stamp_of(files_.client_ca)};
}

void HttpsContextSource::replace(std::shared_ptr<ssl::context> context, const char* why) {
  spdlog::info("event=https_certificate reason={} subject=\"{}\" cert=\"{}\" client_ca=\"{}\"", why,
               subject_of(*context), files_.cert, files_.client_ca);
  context_ = std::move(context);
}

std::shared_ptr<ssl::context> HttpsContextSource::current() {
  std::lock_guard lock(mutex_);
  const auto now = std::chrono::steady_clock::now();
  if (now - last_check_ >= files_.refresh) {
    last_check_ = now;
    // Stamped before reading: a file replaced while being read shows as changed next time.
    std::vector<Stamp> seen = stamps();
    if (seen != stamps_) {
      stamps_ = std::move(seen);
      try {
        replace(make_https_context(files_), "files_changed");
      } catch (const std::exception& e) {
        // Warn, once per change of the files: the certificate in force keeps serving.
        spdlog::warn("event=https_certificate_reload_failed error=\"{}\" kept=\"{}\"", e.what(),
                      subject_of(*context_));
      }
    }
  }
  return context_;
}

void HttpsContextSource::reload() {
  std::vector<Stamp> seen = stamps();
  std::shared_ptr<ssl::context> context;
  try {
    context = make_https_context(files_);
  } catch (...) {
    std::lock_guard lock(mutex_);
    stamps_ = std::move(seen);  // the bad version is reported once, not again at the next check
    throw;
  }
  std::lock_guard lock(mutex_);
  stamps_ = std::move(seen);
  last_check_ = std::chrono::steady_clock::now();
  replace(std::move(context), "reload");
}

}  // namespace filigree::server::http
