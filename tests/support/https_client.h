#pragma once
// An HTTPS client for tests (Boost.Beast over OpenSSL): one kept-alive
// connection that verifies the server as "localhost", and the gRPC-Web wire
// format (frames, a unary request) to speak to the browser port.

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

namespace filigree::test {

namespace beast = boost::beast;
namespace bhttp = boost::beast::http;
namespace net = boost::asio;
namespace ssl = boost::asio::ssl;
namespace fs = std::filesystem;
using tcp = net::ip::tcp;

// ------------------------------------------------------------ gRPC-Web wire format

inline std::string frame_bytes(std::uint8_t flags, const std::string& payload) {
  std::string out(1, static_cast<char>(flags));
  const auto n = static_cast<std::uint32_t>(payload.size());
  for (int s : {24, 16, 8, 0}) out += static_cast<char>((n >> s) & 0xff);
  return out + payload;
}

struct Frames {
  std::vector<std::string> messages;
  std::string trailer;  // "grpc-status:0\r\n…"
  bool well_formed = true;
};

inline Frames parse_frames(std::string body) {
  Frames out;
  while (!body.empty()) {
    if (body.size() < 5 || !out.trailer.empty()) return out.well_formed = false, out;
    std::uint32_t n = 0;
    for (int i = 1; i < 5; ++i) n = (n << 8) | static_cast<std::uint8_t>(body[i]);
    if (body.size() < 5 + std::size_t(n)) return out.well_formed = false, out;
    const std::string payload = body.substr(5, n);
    if (static_cast<std::uint8_t>(body[0]) == 0x80)
      out.trailer = payload;
    else
      out.messages.push_back(payload);
    body.erase(0, 5 + std::size_t(n));
  }
  out.well_formed = out.well_formed && !out.trailer.empty();
  return out;
}

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
