#pragma once
// An HTTPS client for tests (Boost.Beast over OpenSSL): one kept-alive
// connection that verifies the server as "localhost", and the requests to
// speak to the browser port (gRPC-Web frames: grpc_web_frames.h).

#include <cstdint>
#include <filesystem>
#include <memory>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

#include <boost/asio/connect.hpp>
#include <boost/asio/io_context.hpp>
#include <boost/asio/ip/tcp.hpp>
#include <boost/asio/ssl.hpp>
#include <boost/beast/core.hpp>
#include <boost/beast/http.hpp>
#include <boost/beast/ssl.hpp>
#include <google/protobuf/message.h>
#include <openssl/ssl.h>
#include <openssl/x509.h>

#include "support/grpc_web_frames.h"

namespace filigree::test {

namespace beast = boost::beast;
namespace bhttp = boost::beast::http;
namespace net = boost::asio;
namespace ssl = boost::asio::ssl;
namespace fs = std::filesystem;
using tcp = net::ip::tcp;

// ------------------------------------------------------------ requests

inline bhttp::request<bhttp::string_body> grpc_web_request(const std::string& method, const google::protobuf::Message& message) {
  bhttp::request<bhttp::string_body> req{bhttp::verb::post, "/filigree.v1.Filigree/" + method, 11};
  req.set(bhttp::field::host, "localhost");
  req.set(bhttp::field::content_type, "application/grpc-web+proto");
  req.set("x-grpc-web", "1");
  req.body() = frame_bytes(0, message.SerializeAsString());
  req.prepare_payload();
  return req;
}

inline bhttp::request<bhttp::string_body> get(const std::string& target) {
  bhttp::request<bhttp::string_body> req{bhttp::verb::get, target, 11};
  req.set(bhttp::field::host, "localhost");
  return req;
}

// ------------------------------------------------------------ clients

// Runs one asynchronous operation to completion with a 30 s timeout on the
// TCP stream, so that a test fails rather than hangs.
template <class Lowest, class Start>
inline beast::error_code run(net::io_context& ioc, Lowest& lowest, Start start) {
  beast::error_code result;
  lowest.expires_after(std::chrono::seconds(30));
  start([&result](beast::error_code ec, auto&&...) { result = ec; });
  ioc.restart();
  ioc.run();
  return result;
}

// A client TLS context: trusts `ca` (none: trusts nothing), presents
// `cert`/`key` if given.
inline std::unique_ptr<ssl::context> client_context(const std::optional<fs::path>& ca, const std::optional<fs::path>& cert = {},
                                             const std::optional<fs::path>& key = {}) {
  auto ctx = std::make_unique<ssl::context>(ssl::context::tls_client);
  if (ca) ctx->load_verify_file(ca->string());
  ctx->set_verify_mode(ssl::verify_peer);
  if (cert) ctx->use_certificate_chain_file(cert->string());
  if (key) ctx->use_private_key_file(key->string(), ssl::context::pem);
  return ctx;
}

// One HTTPS connection (keep-alive: several exchanges), verifying the server
// as "localhost" like a browser would.
class HttpsClient {
 public:
  // Connects and completes the handshake; throws std::runtime_error with the
  // reason if either fails.
  HttpsClient(const std::string& address, ssl::context& ctx) : stream_(ioc_, ctx) {
    const auto colon = address.rfind(':');
    tcp::resolver resolver(ioc_);
    const auto endpoints = resolver.resolve(address.substr(0, colon), address.substr(colon + 1));
    auto& lowest = beast::get_lowest_layer(stream_);
    beast::error_code ec = run(ioc_, lowest, [&](auto handler) { lowest.async_connect(endpoints, handler); });
    if (ec) throw std::runtime_error("connect: " + ec.message());
    SSL_set_tlsext_host_name(stream_.native_handle(), "localhost");
    stream_.set_verify_callback(ssl::host_name_verification("localhost"));
    ec = run(ioc_, lowest, [&](auto handler) { stream_.async_handshake(ssl::stream_base::client, handler); });
    if (ec) throw std::runtime_error("handshake: " + ec.message());
  }

  bhttp::response<bhttp::string_body> exchange(const bhttp::request<bhttp::string_body>& req) {
    auto& lowest = beast::get_lowest_layer(stream_);
    beast::error_code ec = run(ioc_, lowest, [&](auto handler) { bhttp::async_write(stream_, req, handler); });
    if (ec) throw std::runtime_error("write: " + ec.message());
    bhttp::response_parser<bhttp::string_body> parser;
    parser.body_limit(64u << 20);
    ec = run(ioc_, lowest, [&](auto handler) { bhttp::async_read(stream_, buffer_, parser, handler); });
    if (ec) throw std::runtime_error("read: " + ec.message());
    return parser.release();
  }

  // How the server ended the connection, read after its last response:
  // net::error::eof after a TLS close_notify.
  beast::error_code read_end() {
    char byte;
    auto& lowest = beast::get_lowest_layer(stream_);
    return run(ioc_, lowest, [&](auto handler) { stream_.async_read_some(net::buffer(&byte, 1), handler); });
  }

  // The server certificate's serial number and common name.
  long serial() {
    X509* cert = SSL_get1_peer_certificate(stream_.native_handle());
    if (!cert) return -1;
    const long serial = ASN1_INTEGER_get(X509_get_serialNumber(cert));
    X509_free(cert);
    return serial;
  }
  std::string common_name() {
    X509* cert = SSL_get1_peer_certificate(stream_.native_handle());
    if (!cert) return {};
    char name[256] = {};
    X509_NAME_get_text_by_NID(X509_get_subject_name(cert), NID_commonName, name, sizeof name);
    X509_free(cert);
    return name;
  }

 private:
  net::io_context ioc_;
  beast::ssl_stream<beast::tcp_stream> stream_;
  beast::flat_buffer buffer_;
};

}  // namespace filigree::test
