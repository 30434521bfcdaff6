#pragma once
// What a call brings besides its session: its metadata and, for the raw
// methods, its request as bytes.

#include <string>

#include <grpcpp/grpcpp.h>

namespace filigree::server {

// The call's metadata value for `key`, or empty when it has none.
inline std::string metadata(const grpc::CallbackServerContext& context, const char* key) {
  const auto& md = context.client_metadata();
  const auto it = md.find(key);
  return it == md.end() ? std::string() : std::string(it->second.data(), it->second.size());
}

// The streaming methods are raw (their frames go out serialized once, see
// serialized_frame.h), and so are JoinSession and SetOptions (their meshes,
// session_info_wire.h), GetState (its frames) and GetOverlays, so their
// requests are parsed here; a request that is not a valid message is the
// caller's error.
template <class Message>
grpc::Status parse_request(const grpc::ByteBuffer& bytes, Message& out) {
  grpc::ByteBuffer copy(bytes);  // Deserialize consumes its buffer (a copy shares the slices)
  if (grpc::SerializationTraits<Message>::Deserialize(&copy, &out).ok()) return grpc::Status::OK;
  return {grpc::StatusCode::INVALID_ARGUMENT, "the request is not a valid " + out.GetTypeName() + " message"};
}

}  // namespace filigree::server
