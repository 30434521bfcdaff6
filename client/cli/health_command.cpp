// `filigree health`: asks a server's standard gRPC health service whether it
// serves (container health checks, load balancers' probes). Exit 0: SERVING.

#include <chrono>
#include <cstdio>
#include <future>
#include <string>

#include <CLI/CLI.hpp>
#include <grpcpp/generic/generic_stub.h>
#include <grpcpp/grpcpp.h>

#include "cli/channel_security.h"
#include "cli/commands.h"

namespace filigree::cli {
namespace {

// grpc.health.v1.HealthCheckResponse{status: SERVING} is field 1, varint 1.
constexpr char kServing[] = {0x08, 0x01};

int check(const std::string& server, double timeout_seconds) {
  grpc::GenericStub stub(grpc::CreateChannel(server, channel_credentials()));
  grpc::ClientContext context;
  context.set_deadline(std::chrono::system_clock::now() +
                       std::chrono::milliseconds(static_cast<long>(timeout_seconds * 1000)));
  // An empty HealthCheckRequest (service ""): the whole server. gRPC wants a
  // buffer with a slice, even an empty one.
  grpc::Slice empty(std::string{});
  grpc::ByteBuffer request(&empty, 1), response;
  std::promise<grpc::Status> done;
  stub.UnaryCall(&context, "/grpc.health.v1.Health/Check", grpc::StubOptions(), &request, &response,
                 [&](grpc::Status s) { done.set_value(std::move(s)); });
  const grpc::Status status = done.get_future().get();
  if (!status.ok()) {
    std::fprintf(stderr, "filigree health: %s: %s\n", server.c_str(), status.error_message().c_str());
    return 1;
  }
  grpc::Slice slice;
  const bool serving = response.DumpToSingleSlice(&slice).ok() && slice.size() == sizeof kServing &&
                       std::string(reinterpret_cast<const char*>(slice.begin()), slice.size()) ==
                           std::string(kServing, sizeof kServing);
  std::printf("%s\n", serving ? "SERVING" : "NOT_SERVING");
  return serving ? 0 : 1;
}

}  // namespace

void add_health_command(CLI::App& app) {
  auto server = std::make_shared<std::string>("127.0.0.1:50051");
  auto timeout = std::make_shared<double>(5.0);
  CLI::App* cmd = app.add_subcommand("health", "Ask a server whether it serves (exit 0: SERVING)");
  cmd->add_option("--server", *server, "Server address HOST:PORT");
  cmd->add_option("--timeout", *timeout, "Seconds to wait for the answer");
  cmd->callback([server, timeout] {
    const int code = check(*server, *timeout);
    if (code != 0) throw CLI::RuntimeError(code);
  });
}

}  // namespace filigree::cli
