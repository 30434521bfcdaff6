#pragma once
// Every status the server sends is bounded: a message longer than
// kMaxStatusMessageBytes is cut (at a UTF-8 boundary, marked "…"). Messages
// quote what a client sent (a bad id, a parser's complaint about a data
// URI); unbounded, a 140 KB grpc-message exceeds the client's 8 KB metadata
// limit and the client sees RESOURCE_EXHAUSTED instead of the reason.

#include <cstddef>
#include <memory>
#include <string>

#include <grpcpp/support/server_interceptor.h>

namespace filigree::server {

inline constexpr std::size_t kMaxStatusMessageBytes = 512;

// `message` cut to at most `limit` bytes, never inside a UTF-8 sequence; a
// cut message ends with "…" (within the limit).
std::string bounded_message(const std::string& message, std::size_t limit = kMaxStatusMessageBytes);

// For ServerBuilder::experimental().SetInterceptorCreators.
std::unique_ptr<grpc::experimental::ServerInterceptorFactoryInterface> bounded_status_interceptors();

}  // namespace filigree::server
