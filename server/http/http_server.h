#pragma once
// The HTTP/1.1 face of filigree-server for browsers (Boost.Beast): the built
// web viewer as static files, and gRPC-Web for the same service on the same
// port (grpc_web_bridge.h), with CORS. Its own I/O threads; nothing blocks
// them on gRPC (gRPC completions are posted to each connection's strand).
//
// With HttpOptions::tls, HTTPS only (tls_context.h): the gRPC port's
// certificate, renewed without dropping connections; a plaintext request
// there gets its connection closed.
//
// Routes: OPTIONS anything → CORS preflight (204); POST → gRPC-Web
// (/<package.Service>/<Method>); GET/HEAD → static files (static_files.h).

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
  // Services answered over gRPC-Web (full names, e.g. "filigree.v1.Filigree").
  std::vector<std::string> grpc_web_services;
  // Largest request body; over it, gRPC-Web answers RESOURCE_EXHAUSTED, anything else 413.
  std::size_t max_request_bytes = 4u << 20;
  int threads = 1;
  // Where a gRPC-Web call that names a session (x-session-id) goes: a
  // channel to the replica that serves it, or nullptr for the in-process
  // channel. Empty: always in-process (one machine).
  std::function<std::shared_ptr<grpc::Channel>(const std::string& session_id)> route;
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
