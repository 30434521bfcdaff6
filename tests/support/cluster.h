#pragma once
// A Filigree deployment on loopback for tests and benchmarks (DESIGN §4):
// Redis, N filigree-server replicas sharing it, and nginx as the gRPC load
// balancer routing by x-session-id (consistent hash), each in its own
// process, all in a temporary directory removed at the end.

#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include "support/child_process.h"
#include "support/server_process.h"

namespace filigree::test {

class Cluster {
 public:
  // Needs redis-server and nginx (Debian packages). Replicas get --lease-ms
  // `lease_ms`, and with `http` an HTTP port each (web viewer, gRPC-Web).
  Cluster(const std::string& server_binary, int replicas, int lease_ms = 1500, bool http = false);
  ~Cluster();
  Cluster(const Cluster&) = delete;
  Cluster& operator=(const Cluster&) = delete;

  // nginx's addresses: gRPC, and HTTP (web viewer, gRPC-Web; replicas started with `http`).
  const std::string& lb() const { return lb_; }
  const std::string& lb_http() const { return lb_http_; }
  const std::string& address(int i) const { return addresses_[i]; }
  const std::string& http_address(int i) const { return replicas_[i]->http_address(); }
  const std::string& redis_address() const { return redis_address_; }
  // Replica i is "replica-<i+1>"; -1 for an unknown id.
  int index_of(const std::string& replica_id) const;
  std::filesystem::path data_dir(int i) const;
  // SIGKILL: the replica dies at once, its leases left to expire.
  void kill(int i);
  void pause(int i);
  void resume(int i);
  // SIGTERM and wait; the exit status.
  int terminate(int i);
  void stop_redis();

 private:
  std::filesystem::path dir_;
  std::unique_ptr<ChildProcess> redis_, nginx_;
  std::vector<std::unique_ptr<ServerProcess>> replicas_;
  std::vector<std::string> ids_, addresses_;
  std::string lb_, lb_http_, redis_address_;
};

// The shipped load balancer configuration (docker/nginx/nginx.conf) with the
// compose host names replaced by `grpc_servers` and `http_servers`, its ports
// by 127.0.0.1:grpc_port and :http_port, and its files put under `dir`.
std::string nginx_conf(const std::filesystem::path& dir, int grpc_port, int http_port,
                       const std::vector<std::string>& grpc_servers, const std::vector<std::string>& http_servers);

}  // namespace filigree::test
