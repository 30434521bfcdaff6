#pragma once
// CreateSession over a raw stub, for end-to-end tests written against the
// contract alone: one mesh file's bytes uploaded whole.

#include <cstdint>
#include <functional>
#include <string>

#include <grpcpp/support/status.h>

#include <vector>

#include "filigree/v1/filigree.grpc.pb.h"

namespace filigree::test {

struct Uploaded {
  grpc::Status status;
  v1::CreateSessionResponse::Created created;  // set when status is OK
  std::vector<v1::CreateSessionResponse::Progress> progress;  // as they came
};

// Uploads `bytes` (a mesh in `format`) with `base_vertices`; waits for the end of the call.
Uploaded upload_mesh(v1::Filigree::Stub& stub, const std::string& bytes, const std::string& format,
                     std::uint32_t base_vertices);

// The same with the Begin message changed by `shape` (a proposed id,
// options) and, when not empty, an API key in x-filigree-api-key.
Uploaded upload_mesh(v1::Filigree::Stub& stub, const std::string& bytes, const std::string& format,
                     std::uint32_t base_vertices, const std::function<void(v1::CreateSessionRequest::Begin&)>& shape,
                     const std::string& api_key = {});

}  // namespace filigree::test
