#pragma once
// PlayClip: the server plays a clip of the session's rig through the pipeline.

#include <grpcpp/grpcpp.h>

namespace filigree::server {

class FiligreeService;

// A PlayClip call's reactor (request: a PlayClipRequest; frames out).
grpc::ServerWriteReactor<grpc::ByteBuffer>* new_play_clip_reactor(FiligreeService& service,
                                                                  grpc::CallbackServerContext* context,
                                                                  const grpc::ByteBuffer& request);

}  // namespace filigree::server
