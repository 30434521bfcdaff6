#pragma once
// Drive: a client's stream of poses, answered by the frames that include them.

#include <grpcpp/grpcpp.h>

namespace filigree::server {

class FiligreeService;

// A Drive call's reactor (requests: DriveRequests; frames out). Deletes itself when the call is done.
grpc::ServerBidiReactor<grpc::ByteBuffer, grpc::ByteBuffer>* new_drive_reactor(FiligreeService& service,
                                                                            grpc::CallbackServerContext* context);

}  // namespace filigree::server
