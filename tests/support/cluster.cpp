#include "support/cluster.h"

#include <cstdlib>
#include <fstream>

namespace filigree::test {

namespace fs = std::filesystem;

// nginx: a plain-text HTTP/2 listener; calls with x-session-id hash to a
// replica (consistently: removing a replica moves only its sessions); calls
// without it (uploads that propose no id) spread at random.
std::string nginx_conf(const fs::path& dir, int port, const std::vector<std::string>& replicas) {
  std::string upstream;
  for (const auto& r : replicas) upstream += "    server " + r + " max_fails=1 fail_timeout=5s;\n";
  const std::string d = dir.string();
  return "worker_processes 1;\nerror_log " + d + "/nginx-error.log warn;\npid " + d + "/nginx.pid;\n" +
         "events { worker_connections 512; }\n"
         "http {\n  access_log off;\n"
         "  client_body_temp_path " + d + "/tmp/body;\n  proxy_temp_path " + d + "/tmp/proxy;\n" +
         "  fastcgi_temp_path " + d + "/tmp/fastcgi;\n  uwsgi_temp_path " + d + "/tmp/uwsgi;\n" +
         "  scgi_temp_path " + d + "/tmp/scgi;\n" +
         "  map $http_x_session_id $filigree_route { \"\" $request_id; default $http_x_session_id; }\n"
         "  upstream filigree {\n    hash $filigree_route consistent;\n" + upstream + "  }\n"
         "  server {\n    listen 127.0.0.1:" + std::to_string(port) + " http2;\n    client_max_body_size 0;\n"
         "    location / {\n      grpc_pass grpc://filigree;\n      grpc_next_upstream error timeout;\n"
         "      grpc_connect_timeout 1s;\n      grpc_read_timeout 3600s;\n      grpc_send_timeout 3600s;\n    }\n  }\n}\n";
}

Cluster::Cluster(const std::string& server_binary, int replicas, int lease_ms, bool http) {
  char tmpl[] = "/tmp/filigree-cluster-XXXXXX";
  dir_ = mkdtemp(tmpl);
  fs::create_directories(dir_ / "tmp");
  fs::permissions(dir_, fs::perms::all);  // nginx workers run as nobody when the test runs as root
  fs::permissions(dir_ / "tmp", fs::perms::all);
  const int redis_port = test::free_port();
  redis_ = std::make_unique<ChildProcess>(
      std::vector<std::string>{"redis-server", "--bind", "127.0.0.1", "--port", std::to_string(redis_port), "--save", "",
                               "--appendonly", "no", "--dir", dir_.string()},
      (dir_ / "redis.log").string());
  redis_->wait_for_port(redis_port, 20);
  redis_address_ = "127.0.0.1:" + std::to_string(redis_port);
  for (int i = 0; i < replicas; ++i) {
    ids_.push_back("replica-" + std::to_string(i + 1));
    replicas_.push_back(std::make_unique<ServerProcess>(
        server_binary,
        std::vector<std::string>{"--redis", "127.0.0.1:" + std::to_string(redis_port), "--replica-id", ids_.back(),
                                 "--data-dir", (dir_ / ids_.back()).string(), "--lease-ms", std::to_string(lease_ms)},
        http));
    addresses_.push_back(replicas_.back()->address());
  }
  const int lb_port = test::free_port();
  std::ofstream(dir_ / "nginx.conf") << nginx_conf(dir_, lb_port, addresses_);
  nginx_ = std::make_unique<ChildProcess>(
      std::vector<std::string>{fs::exists("/usr/sbin/nginx") ? "/usr/sbin/nginx" : "nginx", "-p", dir_.string(), "-c",
                               (dir_ / "nginx.conf").string(), "-g", "daemon off;"},
      (dir_ / "nginx.log").string());
  nginx_->wait_for_port(lb_port, 20);
  lb_ = "127.0.0.1:" + std::to_string(lb_port);
}

Cluster::~Cluster() {
  nginx_.reset();
  replicas_.clear();
  redis_.reset();
  std::error_code ec;
  fs::remove_all(dir_, ec);
}

int Cluster::index_of(const std::string& replica_id) const {
  for (std::size_t i = 0; i < ids_.size(); ++i)
    if (ids_[i] == replica_id) return static_cast<int>(i);
  return -1;
}

fs::path Cluster::data_dir(int i) const { return dir_ / ids_[i]; }
void Cluster::kill(int i) { replicas_[i]->kill_now(); }
void Cluster::stop_redis() { redis_.reset(); }

}  // namespace filigree::test
