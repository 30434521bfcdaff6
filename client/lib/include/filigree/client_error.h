#pragma once
// The one exception type of the client library.

#include <stdexcept>
#include <string>

#include <grpcpp/support/status.h>

namespace filigree {

// A failed RPC, or data from the server that cannot be used (code DATA_LOSS).
// what() reads "CODE_NAME: message", e.g. "NOT_FOUND: no session 'x'".
class ClientError : public std::runtime_error {
 public:
  ClientError(grpc::StatusCode code, const std::string& message);
  explicit ClientError(const grpc::Status& status) : ClientError(status.error_code(), status.error_message()) {}

  grpc::StatusCode code() const { return code_; }

 private:
  grpc::StatusCode code_;
};

// "NOT_FOUND", "PERMISSION_DENIED", … (the names of the gRPC specification).
const char* status_code_name(grpc::StatusCode code);

// Throws ClientError(status) unless status is OK.
void throw_if_error(const grpc::Status& status);

}  // namespace filigree
