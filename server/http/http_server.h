#pragma once
// The HTTP/1.1 face of filigree-server for browsers (Boost.Beast): the built
// web viewer as static files, and gRPC-Web for the same service on the same
// port (grpc_web_bridge.h), with CORS for the origins configured (none by
// default: the viewer is served from this port, same origin, and needs
// none). Its own I/O threads; nothing blocks
// them on gRPC (gRPC completions are posted to each connection's strand).
//
// With HttpOptions::tls, HTTPS only (tls_context.h): the gRPC port's
// certificate, renewed without dropping connections; a plaintext request
// there gets its connection closed.
//
// Routes: OPTIONS anything → CORS preflight (204; 403 for an origin not
// allowed); POST → gRPC-Web (/<package.Service>/<Method>); GET/HEAD → static
// files (static_files.h).
//
// Every response says Referrer-Policy: no-referrer (the viewer's address
// carries a token, which must not leave in a Referer) and
// X-Content-Type-Options: nosniff; over HTTPS also Strict-Transport-Security.
// Log lines never show a token or key (log_redaction.h).

#include <chrono>
#include <cstddef>
#include <filesystem>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <grpcpp/channel.h>

#include "server/http/tls_context.h"

namespace filigree::server::http {

struct HttpOptions {
  std::string listen;  // HOST:PORT; port 0 picks a free one
  // Directory of the built viewer; nullopt: "/" and every file answer 404 with a note.
  std::optional<std::filesystem::path> web_root;
  // Served at /server.json (application/json; empty: 404): what a page
  // tells its user about this server (how programs reach it). No secret.
  std::string server_json;
  // Services answered over gRPC-Web (full names, e.g. "filigree.v1.Filigree").
  std::vector<std::string> grpc_web_services;
  // Largest request body; over it, gRPC-Web answers RESOURCE_EXHAUSTED, anything else 413.
  std::size_t max_request_bytes = 4u << 20;
  // Largest request header (request line and fields). Over it: 431 and the
  // connection closes. 16 KiB: far above what a browser sends (cookies
  // included), and what one connection may make the server hold.
  std::size_t max_header_bytes = 16u << 10;

  // Timeouts; each closes the connection when over (a request cut short gets
  // no answer: the timeout may be mid-request). Each is a deadline for the
  // whole phase, not between bytes, so that a client sending one byte at a
  // time (slowloris) is bounded by it all the same.
  //
  // Waiting for the first byte of a request: a new connection's first one,
  // or the next on a kept-alive one. 60 s: browsers reuse a connection for
  // their next call well within it; idle sockets do not pile up for long.
  std::chrono::milliseconds idle_timeout = std::chrono::seconds(60);
  // From the first byte of a request to the end of its header. 10 s: a
  // header is a few hundred bytes, one round trip for any real client.
  std::chrono::milliseconds header_timeout = std::chrono::seconds(10);
  // From the end of the header to the end of the body. 60 s: a full
  // max_request_bytes body at ~70 KB/s.
  std::chrono::milliseconds body_timeout = std::chrono::seconds(60);
  // Writing one response, or one frame of a streamed response, to a client
  // that does not read it. 30 s. (A streamed response has no other bound:
  // a Watch lasts as long as the browser follows it.)
  std::chrono::milliseconds write_timeout = std::chrono::seconds(30);
  // HTTPS: from accept to the end of the TLS handshake. 30 s: a browser may
  // ask its user to choose a client certificate (mutual TLS) meanwhile.
  std::chrono::milliseconds handshake_timeout = std::chrono::seconds(30);

  // Requests served on one kept-alive connection; the last one's response
  // says Connection: close. Bounds what one connection is worth to a client
  // and lets connections move between servers behind a balancer. 1000
  // (nginx's keepalive_requests); 0: no limit.
  unsigned max_requests_per_connection = 1000;
  // Connections open at once (a Watch in a browser holds one for its whole
  // life). Beyond it a new connection is refused at once: plaintext gets a
  // 503 with Retry-After, HTTPS is closed (an answer would need a
  // handshake). Bounds the descriptors and memory idle or slow clients can
  // take; the process's descriptor limit (ulimit -n) must be above it, with
  // room for the gRPC port. 1000; 0: no limit.
  std::size_t max_connections = 1000;

  // gRPC-Web methods whose request is an upload ("/filigree.v1.Filigree/
  // CreateSession": its messages in one body, GrpcWebBridge's request
  // streams): their body may hold up to max_upload_bytes and take
  // upload_timeout to arrive, and at most max_concurrent_uploads are read or
  // running at once (another is refused RESOURCE_EXHAUSTED before its body
  // is read): what browsers can make the server hold is bounded by them.
  std::vector<std::string> upload_paths;
  std::size_t max_upload_bytes = 0;
  std::chrono::milliseconds upload_timeout = std::chrono::seconds(300);
  unsigned max_concurrent_uploads = 2;

  int threads = 1;
  // Where a gRPC-Web call that names a session (x-session-id) goes: a
  // channel to the replica that serves it, or nullptr for the in-process
  // channel. Empty: always in-process (one machine).
  std::function<std::shared_ptr<grpc::Channel>(const std::string& session_id)> route;
  // Origins (scheme://host[:port], as browsers send them in Origin) whose
  // pages may call gRPC-Web here across origins; "*": any page. Empty: none,
  // no Access-Control-Allow-Origin is ever sent (same origin only: the web
  // viewer served on this port needs nothing more).
  std::vector<std::string> cors_origins;
  // Certificate and key: HTTPS instead of HTTP; with client_ca, mutual TLS
  // (browsers then need a client certificate of that CA installed).
  HttpsFiles tls;
};

class HttpServer {
 public:
  // Binds and starts serving. `channel` reaches the service in-process
  // (grpc::Server::InProcessChannel). Throws std::runtime_error if it cannot listen.
  HttpServer(HttpOptions options, std::shared_ptr<grpc::Channel> channel);
  // shutdown() with the default grace.
  ~HttpServer();
  HttpServer(const HttpServer&) = delete;
  HttpServer& operator=(const HttpServer&) = delete;

  // HOST:PORT with the bound port.
  std::string address() const;
  // Serving HTTPS (options.tls given).
  bool https() const;

  // HTTPS: re-reads the certificate, key and client CA files now (they are
  // also re-read by themselves when their modification times change, checked
  // at most every tls.refresh). New connections get the new certificate; open
  // ones keep theirs. Throws std::runtime_error naming the bad file, and keeps
  // the certificate in use, if the files are not a valid pair. Plaintext:
  // does nothing.
  void reload_certificates();

  // Closes the listener; connections already open keep working.
  void stop_accepting();
  // Stops accepting, closes idle connections, lets responses in progress
  // finish for up to `grace` (Watch responses end when their upstream call
  // ends: the service finishes streams with UNAVAILABLE when it shuts down),
  // then cancels what is left and stops the I/O threads. Idempotent.
  void shutdown(std::chrono::milliseconds grace = std::chrono::milliseconds(1000));

  struct Impl;

 private:
  std::unique_ptr<Impl> impl_;
};

}  // namespace filigree::server::http
