// filigree-server: sessions of detailed meshes driven by base poses over gRPC.

#include <csignal>
#include <cstdio>
#include <filesystem>
#include <optional>
#include <thread>

#include <CLI/CLI.hpp>
#include <grpcpp/ext/proto_server_reflection_plugin.h>
#include <grpcpp/health_check_service_interface.h>
#include <grpcpp/grpcpp.h>
#include <spdlog/sinks/stdout_color_sinks.h>
#include <spdlog/spdlog.h>

#include "server/filigree_service.h"
#include "server/http/http_server.h"

namespace {

// --web-root, or by default the viewer built next to the build tree
// (<dir of the executable>/../../web_viewer/dist) when it exists.
std::optional<std::filesystem::path> web_root(const std::string& flag) {
  namespace fs = std::filesystem;
  if (!flag.empty()) {
    if (!fs::is_directory(flag)) throw std::runtime_error("--web-root " + flag + " is not a directory");
    return fs::path(flag);
  }
  std::error_code ec;
  const fs::path exe = fs::read_symlink("/proc/self/exe", ec);
  if (ec) return std::nullopt;
  const fs::path dist = (exe.parent_path() / ".." / ".." / "web_viewer" / "dist").lexically_normal();
  if (fs::is_directory(dist, ec)) return dist;
  return std::nullopt;
}

}  // namespace

int main(int argc, char** argv) {
  using namespace filigree::server;
  CLI::App app{"filigree-server: detail-preserving deformation sessions over gRPC"};
  std::string listen = "127.0.0.1:50051", data_dir;
  ServiceLimits service_limits;
  RegistryLimits registry_limits;
  int max_message_mib = 64;
  std::string log_level = "info";
  std::string http_listen, web_root_flag;
  app.add_option("--listen", listen, "Address to listen on (HOST:PORT; port 0 picks a free one)");
  app.add_option("--data-dir", data_dir, "Where hierarchies and sessions are kept across restarts (empty: memory only)");
  app.add_option("--max-mesh-bytes", service_limits.max_mesh_bytes, "Largest accepted upload in bytes");
  app.add_option("--max-vertices", service_limits.max_vertices, "Largest accepted mesh in vertices");
  app.add_option("--max-sessions", registry_limits.max_sessions, "Most sessions held at once");
  app.add_option("--max-message-mib", max_message_mib, "Largest gRPC message in MiB, each way")->check(CLI::Range(1, 2047));
  app.add_option("--idle-timeout", registry_limits.idle_seconds, "Seconds after which an idle session leaves memory (its record stays)");
  app.add_option("--log-level", log_level, "trace, debug, info, warn, error");
  app.add_option("--http", http_listen,
                 "Also serve browsers over HTTP/1.1 on HOST:PORT: the web viewer's files and gRPC-Web (port 0 picks a "
                 "free one; default: off)");
  app.add_option("--web-root", web_root_flag,
                 "Directory of the built web viewer served over --http (default: <executable dir>/../../web_viewer/dist "
                 "if it exists)");
  CLI11_PARSE(app, argc, argv);
  // Logs go to stderr; stdout carries only the "listening on" (and "http on") lines for scripts.
  spdlog::set_default_logger(spdlog::stderr_color_mt("filigree-server"));
  spdlog::set_level(spdlog::level::from_str(log_level));
  spdlog::set_pattern("%Y-%m-%dT%H:%M:%S.%e level=%l %v");

  // SIGTERM/SIGINT are taken by sigwait below; block them before any thread starts.
  sigset_t signals;
  sigemptyset(&signals);
  sigaddset(&signals, SIGTERM);
  sigaddset(&signals, SIGINT);
  pthread_sigmask(SIG_BLOCK, &signals, nullptr);

  try {
    HierarchyCache cache(data_dir.empty() ? std::filesystem::path() : std::filesystem::path(data_dir) / "hierarchies");
    SessionRegistry registry(cache, data_dir, registry_limits);
    const std::size_t restored = registry.restore();
    FiligreeService service(registry, cache, service_limits);

    grpc::EnableDefaultHealthCheckService(true);
    grpc::reflection::InitProtoReflectionServerBuilderPlugin();
    grpc::ServerBuilder builder;
    int port = 0;
    builder.AddListeningPort(listen, grpc::InsecureServerCredentials(), &port);
    builder.SetMaxReceiveMessageSize(max_message_mib << 20);
    builder.SetMaxSendMessageSize(max_message_mib << 20);
    builder.RegisterService(&service);
    std::unique_ptr<grpc::Server> server = builder.BuildAndStart();
    if (!server || port == 0) {
      spdlog::error("event=listen_failed address={}", listen);
      return 1;
    }
    // Browsers: static files and gRPC-Web, bridged in-process to the same service.
    std::unique_ptr<http::HttpServer> http_server;
    if (!http_listen.empty()) {
      http::HttpOptions http_options;
      http_options.listen = http_listen;
      http_options.web_root = web_root(web_root_flag);
      http_options.grpc_web_services = {filigree::v1::Filigree::service_full_name()};
      grpc::ChannelArguments channel_args;  // the server enforces --max-message-mib
      channel_args.SetMaxReceiveMessageSize(-1);
      channel_args.SetMaxSendMessageSize(-1);
      http_server = std::make_unique<http::HttpServer>(std::move(http_options), server->InProcessChannel(channel_args));
    }
    const std::string host = listen.substr(0, listen.rfind(':'));
    spdlog::info("event=listening address={}:{} data_dir=\"{}\" restored_sessions={}", host, port, data_dir, restored);
    // Tests and scripts read the port from this line on stdout.
    std::printf("listening on %s:%d\n", host.c_str(), port);
    if (http_server) std::printf("http on %s\n", http_server->address().c_str());
    std::fflush(stdout);

    std::atomic<bool> stopping{false};
    std::thread maintenance([&] {
      while (!stopping) {
        for (int i = 0; i < 10 && !stopping; ++i) std::this_thread::sleep_for(std::chrono::milliseconds(100));
        registry.maintain();
      }
    });

    int signal = 0;
    sigwait(&signals, &signal);
    spdlog::info("event=shutdown signal={}", signal);
    if (http_server) http_server->stop_accepting();
    // Drain: uploads finish, streams end with UNAVAILABLE, records are written.
    service.drain();
    registry.shutdown();
    // Watch responses end with the streams just finished; idle connections close.
    if (http_server) {
      http_server->shutdown();
      http_server.reset();
    }
    // Streams are already finished; this only bounds unary calls still in flight.
    server->Shutdown(std::chrono::system_clock::now() + std::chrono::seconds(1));
    stopping = true;
    maintenance.join();
    registry.shutdown();
    spdlog::info("event=stopped");
    return 0;
  } catch (const std::exception& e) {
    spdlog::error("event=fatal error=\"{}\"", e.what());
    return 1;
  }
}
