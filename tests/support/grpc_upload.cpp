#include "support/grpc_upload.h"

#include <grpcpp/grpcpp.h>

#include "filigree/v1/filigree.grpc.pb.h"

namespace filigree::test {

Uploaded upload_mesh(v1::Filigree::Stub& stub, const std::string& bytes, const std::string& format,
                     std::uint32_t base_vertices) {
  return upload_mesh(stub, bytes, format, base_vertices, {});
}

Uploaded upload_mesh(v1::Filigree::Stub& stub, const std::string& bytes, const std::string& format,
                     std::uint32_t base_vertices, const std::function<void(v1::CreateSessionRequest::Begin&)>& shape,
                     const std::string& api_key) {
  grpc::ClientContext ctx;
  if (!api_key.empty()) ctx.AddMetadata("x-filigree-api-key", api_key);
  auto stream = stub.CreateSession(&ctx);
  v1::CreateSessionRequest message;
  message.mutable_begin()->set_format(format);
  message.mutable_begin()->set_total_bytes(bytes.size());
  message.mutable_begin()->mutable_options()->set_base_vertices(base_vertices);
  if (shape) shape(*message.mutable_begin());
  stream->Write(message);
  message.set_chunk(bytes);
  stream->Write(message);
  stream->WritesDone();
  Uploaded out;
  v1::CreateSessionResponse r;
  while (stream->Read(&r)) {
    if (r.has_created()) out.created = r.created();
    if (r.has_progress()) out.progress.push_back(r.progress());
  }
  out.status = stream->Finish();
  return out;
}

}  // namespace filigree::test
