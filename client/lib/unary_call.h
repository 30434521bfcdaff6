#pragma once
// One unary call on a session (inside the client library): the session's
// metadata and a deadline set, a failure thrown as ClientError.

#include <chrono>
#include <string>

#include <grpcpp/grpcpp.h>

#include "filigree/call_metadata.h"
#include "filigree/client_error.h"
#include "filigree/v1/filigree.grpc.pb.h"

namespace filigree {

template <class Request, class Response>
Response unary_call(v1::Filigree::Stub& stub,
                    grpc::Status (v1::Filigree::Stub::*method)(grpc::ClientContext*, const Request&, Response*),
                    const std::string& session_id, const std::string& token, const Request& request, Routing routing,
                    std::chrono::milliseconds timeout) {
  grpc::ClientContext context;
  set_session_metadata(context, session_id, token, routing);
  context.set_deadline(std::chrono::system_clock::now() + timeout);
  Response response;
  throw_if_error((stub.*method)(&context, request, &response));
  return response;
}

}  // namespace filigree
