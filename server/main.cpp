// filigree-server: sessions of detailed meshes driven by base poses over gRPC.

#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <optional>
#include <thread>
#include <vector>

#include <unistd.h>

#include <CLI/CLI.hpp>
#include <grpcpp/ext/proto_server_reflection_plugin.h>
#include <grpcpp/health_check_service_interface.h>
#include <grpcpp/grpcpp.h>
#include <spdlog/sinks/stdout_color_sinks.h>
#include <spdlog/spdlog.h>

#include "server/api_keys.h"
#include "server/bounded_status.h"
#include "server/connection_guard.h"
#include "server/filigree_service.h"
#include "server/http/http_server.h"
#include "server/listen_address.h"
#include "server/replica_router.h"
#include "server/resident_memory.h"
#include "server/state/file_session_store.h"
#include "server/state/redis_client.h"
#include "server/state/redis_hierarchy_store.h"
#include "server/state/redis_session_store.h"
#include "server/tls_files.h"
#include "server/verified_tls_files.h"

namespace {

// /server.json on the browser port: how a program reaches the gRPC port
// (grpc_host empty: the page's own host, for a wildcard --listen), whether
// it speaks TLS and whether creating sessions needs an API key.
std::string server_json(const std::string& listen, int port, bool tls, bool api_keys) {
  std::string host = listen.rfind("unix:", 0) == 0 ? "" : listen.substr(0, listen.rfind(':'));
  if (host == "0.0.0.0" || host == "[::]" ||
      host.find_first_not_of("abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ0123456789.-:[]") != std::string::npos)
    host.clear();
  return "{\"grpc_host\":\"" + host + "\",\"grpc_port\":" + std::to_string(port) + ",\"tls\":" + (tls ? "true" : "false") +
         ",\"api_keys\":" + (api_keys ? "true" : "false") + "}";
}

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

std::string host_name() {
  char name[256] = {};
  if (gethostname(name, sizeof name - 1) != 0 || !name[0]) return "localhost";
  return name;
}

// The Redis password: the first line of `file` (trailing whitespace trimmed),
// or without a file $FILIGREE_REDIS_PASSWORD; empty: none. Never an option's
// value: a command line is readable by every user of the machine (ps).
std::string redis_password(const std::string& file) {
  if (file.empty()) {
    const char* env = std::getenv("FILIGREE_REDIS_PASSWORD");
    return env ? env : "";
  }
  std::ifstream in(file);
  std::string line;
  // An empty file only sets eof; a directory or a read error fails without it.
  if (!in || (!std::getline(in, line) && !in.eof())) throw std::runtime_error("cannot read --redis-password-file " + file);
  line.erase(line.find_last_not_of(" \t\r\n\v\f") + 1);  // all blank: npos + 1 == 0 erases everything
  if (line.empty()) throw std::runtime_error("--redis-password-file " + file + " has no password on its first line");
  return line;
}

// Session records hold editor tokens, and hierarchy files are loaded in
// place: another user who can write in --data-dir (or its subdirectories)
// could replace them. Said at start, once; the server still starts (the
// directory is the operator's to fix).
void warn_if_writable_by_others(const std::filesystem::path& data) {
  namespace fs = std::filesystem;
  if (data.empty()) return;
  for (const fs::path& dir : {data, data / "sessions", data / "hierarchies"}) {
    std::error_code ec;
    const fs::file_status st = fs::status(dir, ec);
    if (ec || !fs::is_directory(st)) continue;
    const fs::perms p = st.permissions();
    const bool others = (p & fs::perms::others_write) != fs::perms::none;
    const bool group = (p & fs::perms::group_write) != fs::perms::none;
    if (!others && !group) continue;
    spdlog::warn("event=data_dir_writable_by_others dir=\"{}\" mode={:04o} writable_by={} advice=\"chmod 700: session "
                 "records hold editor tokens\"",
                 dir.string(), static_cast<unsigned>(p) & 07777u, others ? "everyone" : "group");
  }
}

}  // namespace

int main(int argc, char** argv) {
  using namespace filigree::server;
  keep_large_buffers_out_of_the_heap();
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
  app.add_option("--max-streams-per-session", service_limits.max_streams_per_session,
                 "Most streams (drivers, watchers, clips) one session serves at once; 0: no limit");
  int max_streams_per_connection = 100;
  app.add_option("--max-streams-per-connection", max_streams_per_connection,
                 "Most calls one gRPC connection (HTTP/2) carries at once; more wait for one to end; 0: gRPC's default "
                 "(no limit)")
      ->check(CLI::NonNegativeNumber);
  std::size_t max_connections = 0;
  app.add_option("--max-connections", max_connections,
                 "Most connections to the gRPC port at once; more are closed as they come. 0: as many as the "
                 "process's open-file limit allows (three descriptors each), with room for everything else")
      ->check(CLI::NonNegativeNumber);
  app.add_option("--max-sessions", registry_limits.max_sessions, "Most sessions held at once");
  std::uint64_t max_memory_mib = 0;
  app.add_option("--max-memory", max_memory_mib,
                 "Resident memory in MiB beyond which uploads are refused (RESOURCE_EXHAUSTED) once idle sessions "
                 "are evicted from memory (their records stay); 0: no limit");
  app.add_option("--preprocessing-slots", service_limits.preprocessing_slots,
                 "Uploads preprocessed at once, at a lower CPU priority than live sessions; more wait their turn")
      ->check(CLI::Range(1u, 64u));
  app.add_option("--session-loads", service_limits.session_loads,
                 "Sessions loaded from --data-dir or the shared store at once (evicted, or another replica's); "
                 "more wait their turn off gRPC's threads; 0: one per core")
      ->check(CLI::Range(0u, 64u));
  app.add_option("--upload-timeout", service_limits.upload_seconds,
                 "Seconds an upload may take to send its bytes (DEADLINE_EXCEEDED after); 0: no limit")
      ->check(CLI::NonNegativeNumber);
  app.add_option("--max-message-mib", max_message_mib, "Largest gRPC message in MiB, each way")->check(CLI::Range(1, 2047));
  std::size_t history_mib = registry_limits.history.bytes >> 20;
  app.add_option("--history-entries", registry_limits.history.entries,
                 "Most entries each session's edit history keeps (the oldest go first; 0: no history)")
      ->check(CLI::Range(0, 1000000));
  app.add_option("--history-mib", history_mib, "Most memory each session's edit history holds, in MiB")->check(CLI::Range(1, 65536));
  app.add_option("--idle-timeout", registry_limits.idle_seconds, "Seconds after which an idle session leaves memory (its record stays)");
  app.add_option("--log-level", log_level, "trace, debug, info, warn, error");
  TlsFiles tls;
  app.add_option("--tls-cert", tls.cert, "Server certificate chain (PEM): TLS on the gRPC port; re-read when it changes");
  app.add_option("--tls-key", tls.key, "The certificate's private key (PEM)");
  app.add_option("--tls-refresh", tls.refresh_seconds,
                 "Seconds between looks at --tls-cert, --tls-key and the CA files; a changed pair is checked (parse, "
                 "key match, validity, strength) and put in force only if good (SIGHUP: look now)")
      ->check(CLI::Range(1u, 86400u));
  app.add_option("--tls-client-ca", tls.client_ca, "CA bundle (PEM) of client certificates: mutual TLS, clients without one are refused");
  app.add_option("--peer-ca", tls.peer_ca,
                 "CA bundle (PEM) the other replicas' certificates chain to, for calls this replica forwards to them "
                 "over TLS (default: the system CA store)");
  std::string api_keys_path;
  app.add_option("--api-keys", api_keys_path,
                 "File of API keys (NAME SHA256 [quotas]; `filigree api-key` makes one): CreateSession and "
                 "ListSessions then need x-filigree-api-key; re-read on SIGHUP")
      ->check(CLI::ExistingFile);
  bool insecure = false;
  app.add_flag("--insecure", insecure,
               "Allow plaintext on a --listen or --http address other machines can reach (TLS ends before this "
               "server: a proxy or a service mesh)");
  app.add_option("--http", http_listen,
                 "Also serve browsers over HTTP/1.1 on HOST:PORT: the web viewer's files and gRPC-Web (port 0 picks a "
                 "free one; default: off)");
  std::vector<std::string> cors_origins;
  app.add_option("--http-cors-origin", cors_origins,
                 "An origin (scheme://host[:port]) whose pages may call gRPC-Web on --http across origins; repeat for "
                 "several, * for any page (default: none; the web viewer served on --http is same-origin and needs none)");
  app.add_option("--web-root", web_root_flag,
                 "Directory of the built web viewer served over --http (default: <executable dir>/../../web_viewer/dist "
                 "if it exists)");
  std::string redis_address, replica_id, advertise, redis_prefix = "filigree:", redis_password_file;
  RedisCredentials redis_credentials;
  int lease_ms = 3000;
  auto* redis_option = app.add_option(
      "--redis", redis_address,
      "HOST:PORT of a Redis shared by replicas: hierarchies, session records and ownership leases live "
      "there, so any replica can take a session over (default: none; this process is the only replica)");
  app.add_option("--redis-password-file", redis_password_file,
                 "File whose first line is the Redis password, sent with AUTH on every connection (default: "
                 "$FILIGREE_REDIS_PASSWORD if set, else no AUTH)")
      ->needs(redis_option);
  app.add_option("--redis-user", redis_credentials.user,
                 "Redis 6 ACL user to authenticate as, with the password (default: the password alone)")
      ->needs(redis_option);
  // TLS to Redis always verifies the server: there is no option to skip it.
  RedisTlsOptions redis_tls;
  auto* redis_tls_flag =
      app.add_flag("--redis-tls", redis_tls.enabled,
                   "Reach Redis over TLS (Redis' --tls-port), verifying its certificate and name")
          ->needs(redis_option);
  app.add_option("--redis-tls-ca", redis_tls.ca_file,
                 "CA bundle (PEM) Redis' certificate must chain to (default: the system CA store)")
      ->needs(redis_tls_flag);
  app.add_option("--redis-tls-cert", redis_tls.cert_file,
                 "Client certificate chain (PEM) for a Redis with tls-auth-clients; with --redis-tls-key")
      ->needs(redis_tls_flag);
  app.add_option("--redis-tls-key", redis_tls.key_file, "The client certificate's private key (PEM, unencrypted)")
      ->needs(redis_tls_flag);
  app.add_option("--redis-tls-server-name", redis_tls.server_name,
                 "Name sent as SNI and verified in Redis' certificate (default: the host of --redis)")
      ->needs(redis_tls_flag);
  app.add_option("--replica-id", replica_id, "This replica's unique name (default: <hostname>-<pid>)");
  app.add_option("--advertise", advertise,
                 "HOST:PORT at which clients reach this replica directly, told by LocateSession (default: the "
                 "listening address, with the host name for 0.0.0.0)");
  app.add_option("--lease-ms", lease_ms, "Ownership lease of a session (with --redis): how long a dead replica's "
                                         "sessions wait before another replica takes them over")
      ->check(CLI::Range(300, 600000));
  app.add_option("--redis-prefix", redis_prefix, "Prefix of every Redis key (several deployments on one Redis)");
  CLI11_PARSE(app, argc, argv);
  registry_limits.history.bytes = history_mib << 20;
  service_limits.max_memory_bytes = max_memory_mib << 20;
  service_limits.max_message_bytes = static_cast<std::uint64_t>(max_message_mib) << 20;
  // Logs go to stderr; stdout carries only the "listening on" (and "http on") lines for scripts.
  spdlog::set_default_logger(spdlog::stderr_color_mt("filigree-server"));
  spdlog::set_level(spdlog::level::from_str(log_level));
  spdlog::set_pattern("%Y-%m-%dT%H:%M:%S.%e level=%l %v");

  // SIGTERM/SIGINT are taken by sigwait below; block them before any thread starts.
  sigset_t signals;
  sigemptyset(&signals);
  sigaddset(&signals, SIGTERM);
  sigaddset(&signals, SIGINT);
  sigaddset(&signals, SIGHUP);  // reload the API keys
  pthread_sigmask(SIG_BLOCK, &signals, nullptr);

  try {
    // Secure by default: plaintext stays on this machine unless the operator says otherwise.
    if (!insecure && !is_loopback_only(listen) && !tls.enabled())
      throw std::runtime_error("--listen " + listen + " is reachable from other machines without TLS: tokens and meshes "
                               "would cross the network in clear. Give --tls-cert and --tls-key, or --insecure if TLS "
                               "ends before this server");
    // With --tls-cert, --http serves HTTPS with the same certificate.
    if (!insecure && !http_listen.empty() && !is_loopback_only(http_listen) && !tls.enabled())
      throw std::runtime_error("--http " + http_listen + " is reachable from other machines without TLS: give --tls-cert "
                               "and --tls-key (HTTPS there too, same certificate), or --insecure if TLS ends before "
                               "this server");
    // Only replicas serving browsers forward calls to each other.
    const bool forwards = !redis_address.empty() && !http_listen.empty();
    // The certificate and key are read and checked before anything else
    // starts: a pair that could only fail handshakes refuses the start, saying why.
    std::unique_ptr<VerifiedTlsFiles> verified_tls;
    if (tls.enabled()) {
      if (!forwards && !tls.peer_ca.empty())
        throw std::runtime_error("--peer-ca is for replicas (--redis) that serve browsers (--http): without both, nothing forwards");
      verified_tls = std::make_unique<VerifiedTlsFiles>(tls);
    }
    const std::filesystem::path data = data_dir;
    warn_if_writable_by_others(data);
    // One machine: records as files. Replicas: records, leases and hierarchies in Redis
    // (hierarchy files stay in --data-dir as a local cache).
    std::shared_ptr<RedisClient> redis;
    std::unique_ptr<SessionStore> store;
    RedisSessionStore* redis_store = nullptr;
    std::unique_ptr<HierarchyStore> shared_hierarchies;
    if (!redis_address.empty()) {
      redis_credentials.password = redis_password(redis_password_file);
      if (!redis_credentials.user.empty() && redis_credentials.password.empty())
        throw std::runtime_error("--redis-user needs a password: --redis-password-file or FILIGREE_REDIS_PASSWORD");
      if (redis_tls.cert_file.empty() != redis_tls.key_file.empty())
        throw std::runtime_error("--redis-tls-cert and --redis-tls-key go together");
      redis = std::make_shared<RedisClient>(redis_address, std::chrono::milliseconds(std::max(200, lease_ms / 3)),
                                            redis_credentials, redis_tls);
      if (replica_id.empty()) replica_id = host_name() + "-" + std::to_string(getpid());
      auto made = std::make_unique<RedisSessionStore>(redis, RedisSessionStoreOptions{redis_prefix, replica_id, "",
                                                                                      std::chrono::milliseconds(lease_ms)});
      redis_store = made.get();
      store = std::move(made);
      shared_hierarchies = std::make_unique<RedisHierarchyStore>(redis, redis_prefix);
      registry_limits.lease_seconds = lease_ms / 1000.0;
    } else {
      store = std::make_unique<FileSessionStore>(data.empty() ? data : data / "sessions");
    }
    HierarchyCache cache(data.empty() ? data : data / "hierarchies", shared_hierarchies.get());
    SessionRegistry registry(cache, *store, registry_limits);
    const std::size_t restored = registry.restore();
    // One machine: hierarchy files no session uses go (replicas share them through Redis).
    if (!store->shared()) registry.collect_hierarchies();
    FiligreeService service(registry, cache, service_limits);
    if (!api_keys_path.empty()) {
      auto keys = std::make_shared<const ApiKeys>(ApiKeys::load(api_keys_path));
      spdlog::info("event=api_keys file=\"{}\" keys={}", api_keys_path, keys->size());
      service.set_api_keys(std::move(keys));
    }

    grpc::EnableDefaultHealthCheckService(true);
    grpc::reflection::InitProtoReflectionServerBuilderPlugin();
    grpc::ServerBuilder builder;
    int port = 0;
    // TCP connections reach gRPC through a ConnectionGuard (a cap, and
    // accepting that survives running out of descriptors, which gRPC 1.51's
    // own does not), relayed to gRPC on a unix socket in a private folder.
    // A unix: --listen is local already and goes to gRPC directly.
    std::unique_ptr<ConnectionGuard> guard;
    std::unique_ptr<PrivateSocketDir> socket_dir;
    if (listen.rfind("unix:", 0) == 0) {
      builder.AddListeningPort(listen, server_credentials(tls, verified_tls.get()), &port);
    } else {
      socket_dir = std::make_unique<PrivateSocketDir>();
      ConnectionGuardOptions guard_options;
      guard_options.listen = listen;
      guard_options.upstream = socket_dir->socket();
      // Room for files, sessions' stores and the browser port's connections.
      constexpr std::size_t kReservedDescriptors = 1024 + 512;
      const std::size_t budget = connection_budget(kReservedDescriptors);
      if (max_connections > budget)
        spdlog::warn("event=max_connections_lowered asked={} allowed={} reason=\"the open-file limit (ulimit -n) leaves room "
                     "for {} relayed connections\"",
                     max_connections, budget, budget);
      guard_options.max_connections = max_connections ? std::min(max_connections, budget) : budget;
      guard = std::make_unique<ConnectionGuard>(guard_options);
      port = guard->port();
      int unix_port = 0;
      builder.AddListeningPort("unix:" + socket_dir->socket().string(), server_credentials(tls, verified_tls.get()), &unix_port);
      spdlog::info("event=connection_guard max_connections={}", guard_options.max_connections);
    }
    // A wrong --peer-ca failed above (VerifiedTlsFiles), not on the first forwarded call.
    const std::shared_ptr<grpc::ChannelCredentials> peers = forwards ? peer_credentials(tls, verified_tls.get()) : nullptr;
    builder.SetMaxReceiveMessageSize(max_message_mib << 20);
    builder.SetMaxSendMessageSize(max_message_mib << 20);
    // gRPC allows SO_REUSEPORT by default: a second server started on the same
    // port by mistake would silently take half of the connections. Refuse instead.
    builder.AddChannelArgument(GRPC_ARG_ALLOW_REUSEPORT, 0);
    // One client connection cannot hold unbounded calls (each a stream's
    // buffers and, for Watch, a writer); per connection, so unlike
    // --max-streams-per-session it also bounds calls spread over sessions.
    if (max_streams_per_connection > 0)
      builder.AddChannelArgument(GRPC_ARG_MAX_CONCURRENT_STREAMS, max_streams_per_connection);
    std::vector<std::unique_ptr<grpc::experimental::ServerInterceptorFactoryInterface>> interceptors;
    interceptors.push_back(bounded_status_interceptors());
    builder.experimental().SetInterceptorCreators(std::move(interceptors));
    builder.RegisterService(&service);
    std::unique_ptr<grpc::Server> server = builder.BuildAndStart();
    if (!server || port == 0) {
      spdlog::error("event=listen_failed address={}", listen);
      return 1;
    }
    if (guard) guard->start();
    // Browsers: static files and gRPC-Web, bridged in-process to the same service.
    std::unique_ptr<http::HttpServer> http_server;
    if (!http_listen.empty()) {
      http::HttpOptions http_options;
      http_options.listen = http_listen;
      http_options.web_root = web_root(web_root_flag);
      http_options.grpc_web_services = {filigree::v1::Filigree::service_full_name()};
      http_options.cors_origins = cors_origins;
      // Browsers upload through the page: CreateSession's messages in one
      // body, up to --max-mesh-bytes (and its framing), two at a time.
      http_options.upload_paths = {"/" + std::string(filigree::v1::Filigree::service_full_name()) + "/CreateSession"};
      http_options.server_json = server_json(listen, port, tls.enabled(), !api_keys_path.empty());
      http_options.max_upload_bytes = service_limits.max_mesh_bytes + (1u << 20);
      if (service_limits.upload_seconds > 0)
        http_options.upload_timeout = std::chrono::milliseconds(static_cast<long long>(service_limits.upload_seconds * 1000));
      // HTTPS with the gRPC port's files, mutual TLS included: otherwise --http
      // would reach the same service around --tls-client-ca.
      http_options.tls = {tls.cert, tls.key, tls.client_ca, std::chrono::seconds(tls.refresh_seconds)};
      // Replicas: a browser's calls go to the replica that serves the session.
      if (redis)
        http_options.route = [router = std::make_shared<ReplicaRouter>(registry, peers)](const std::string& id) {
        return router->channel_for(id);
      };
      grpc::ChannelArguments channel_args;  // the server enforces --max-message-mib
      channel_args.SetMaxReceiveMessageSize(-1);
      channel_args.SetMaxSendMessageSize(-1);
      http_server = std::make_unique<http::HttpServer>(std::move(http_options), server->InProcessChannel(channel_args));
    }
    const std::string host = listen.substr(0, listen.rfind(':'));
    if (redis) {
      if (advertise.empty()) advertise = (host == "0.0.0.0" || host == "[::]" ? host_name() : host) + ":" + std::to_string(port);
      // The port is known only now (--listen HOST:0).
      redis_store->set_advertise(advertise);
      const std::string auth = redis_credentials.password.empty() ? "none"
                               : redis_credentials.user.empty()     ? "password"
                                                                    : "user:" + redis_credentials.user;
      const char* transport = !redis_tls.enabled ? "plaintext" : redis_tls.cert_file.empty() ? "tls" : "mutual-tls";
      spdlog::info("event=replica replica_id={} advertise={} redis={} redis_auth={} redis_transport={} lease_ms={}",
                   replica_id, advertise, redis_address, auth, transport, lease_ms);
    }
    spdlog::info("event=listening address={}:{} data_dir=\"{}\" restored_sessions={} transport={}", host, port, data_dir,
                 restored, !tls.enabled() ? "plaintext" : tls.client_ca.empty() ? "tls" : "mutual-tls");
    // Tests and scripts read the port from this line on stdout.
    std::printf("listening on %s:%d\n", host.c_str(), port);
    if (http_server) std::printf("http on %s\n", http_server->address().c_str());
    std::fflush(stdout);

    std::atomic<bool> stopping{false};
    std::thread maintenance([&] {
      // Leases are renewed three times per lease; records (one machine) once a second.
      const int tick_ms = redis ? lease_ms / 3 : 1000;
      while (!stopping) {
        for (int t = 0; t < tick_ms && !stopping; t += 50) std::this_thread::sleep_for(std::chrono::milliseconds(50));
        registry.maintain();
        service.expire_uploads();
      }
    });

    int signal = 0;
    // SIGHUP: re-read the API keys and the certificate files now. A broken
    // file keeps what is in force. (Both ports also re-read their certificate
    // files by themselves within TlsFiles::refresh_seconds.)
    while (sigwait(&signals, &signal) == 0 && signal == SIGHUP) {
      if (!api_keys_path.empty()) {
        try {
          auto keys = std::make_shared<const ApiKeys>(ApiKeys::load(api_keys_path));
          const std::size_t count = keys->size();
          service.set_api_keys(std::move(keys));  // in force before the log says so
          spdlog::info("event=api_keys_reloaded keys={}", count);
        } catch (const std::exception& e) {
          spdlog::error("event=api_keys_reload_failed error=\"{}\"", e.what());
        }
      }
      if (verified_tls) verified_tls->refresh();  // logs what it put in force or refused
      if (http_server && http_server->https()) {
        try {
          http_server->reload_certificates();
          spdlog::info("event=https_certificate_reloaded");
        } catch (const std::exception& e) {
          spdlog::error("event=https_certificate_reload_failed error=\"{}\"", e.what());
        }
      }
    }
    spdlog::info("event=shutdown signal={}", signal);
    if (http_server) http_server->stop_accepting();
    // Drain: uploads finish (leases are still renewed meanwhile), then streams
    // end with UNAVAILABLE, records are written and leases released.
    service.drain();
    stopping = true;
    maintenance.join();
    registry.shutdown();
    // Watch responses end with the streams just finished; idle connections close.
    if (http_server) {
      http_server->shutdown();
      http_server.reset();
    }
    // Streams are already finished; this only bounds unary calls still in
    // flight (a pose or a join takes milliseconds) and idle client
    // connections, which hold Shutdown to its deadline: SIGTERM ends the
    // server within a second.
    server->Shutdown(std::chrono::system_clock::now() + std::chrono::milliseconds(250));
    if (guard) guard->stop();
    registry.shutdown();
    spdlog::info("event=stopped");
    return 0;
  } catch (const std::exception& e) {
    spdlog::error("event=fatal error=\"{}\"", e.what());
    return 1;
  }
}
