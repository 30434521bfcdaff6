#pragma once
// Watch and Follow: the streams that read a session's frames.

#include <grpcpp/grpcpp.h>

namespace filigree::server {

class FiligreeService;

// A Watch call's reactor (request: a WatchRequest; frames out).
grpc::ServerWriteReactor<grpc::ByteBuffer>* new_watch_reactor(FiligreeService& service, grpc::CallbackServerContext* context,
                                                              const grpc::ByteBuffer& request);
// A Follow call's reactor (requests: FollowRequests; frames out).
grpc::ServerBidiReactor<grpc::ByteBuffer, grpc::ByteBuffer>* new_follow_reactor(FiligreeService& service,
                                                                             grpc::CallbackServerContext* context);

}  // namespace filigree::server
