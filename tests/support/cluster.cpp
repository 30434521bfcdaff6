#include "support/cluster.h"

#include <algorithm>
#include <cstdlib>
#include <fstream>
#include <sstream>
#include <stdexcept>

namespace filigree::test {

namespace fs = std::filesystem;

namespace {

std::string read_file(const fs::path& file) {
  std::ifstream in(file);
  if (!in) throw std::runtime_error("cannot read " + file.string());
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

// Replaces the line containing `needle` (which must be there) with `lines`.
void replace_line(std::string& text, const std::string& needle, const std::string& lines) {
  const auto at = text.find(needle);
  if (at == std::string::npos) throw std::runtime_error("docker/nginx/nginx.conf has no '" + needle + "'");
  const auto newline_before = text.rfind('\n', at);
  const std::size_t begin = newline_before == std::string::npos ? 0 : newline_before + 1;
  const std::size_t end = std::min(text.find('\n', at), text.size());
  text = text.substr(0, begin) + lines + text.substr(end);
}

}  // namespace

std::string nginx_conf(const fs::path& dir, int grpc_port, int http_port, const std::vector<std::string>& grpc_servers,
                       const std::vector<std::string>& http_servers) {
  std::string conf = read_file(fs::path(FILIGREE_SOURCE_DIR) / "docker" / "nginx" / "nginx.conf");
  const std::string d = dir.string();
  replace_line(conf, "pid /tmp/nginx.pid;", "pid " + d + "/nginx.pid;");
  replace_line(conf, "access_log /dev/stdout;",
               "  access_log off;\n  client_body_temp_path " + d + "/tmp/body;\n  proxy_temp_path " + d +
                   "/tmp/proxy;\n  fastcgi_temp_path " + d + "/tmp/fastcgi;\n  uwsgi_temp_path " + d +
                   "/tmp/uwsgi;\n  scgi_temp_path " + d + "/tmp/scgi;");
  replace_line(conf, "error_log /dev/stderr warn;", "  error_log " + d + "/nginx-error.log warn;");
  // The compose host names become the replicas' loopback addresses.
  for (std::size_t i = 0; i < 3; ++i) {
    const std::string n = std::to_string(i + 1);
    std::string grpc, http;
    // (Appends, not `"…" + string` chains: GCC 12 warns falsely on those, -Wrestrict.)
    for (std::size_t k = i; k < grpc_servers.size(); k += 3) grpc.append("    server ").append(grpc_servers[k]).append(";\n");
    for (std::size_t k = i; k < http_servers.size(); k += 3) http.append("    server ").append(http_servers[k]).append(";\n");
    replace_line(conf, "server filigree-" + n + ":50051;", grpc);
    replace_line(conf, "server filigree-" + n + ":8080;", http);
  }
  replace_line(conf, "listen 8443 http2;", "    listen 127.0.0.1:" + std::to_string(grpc_port) + " http2;");
  replace_line(conf, "listen 8080;", "    listen 127.0.0.1:" + std::to_string(http_port) + ";");
  return conf;
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
  const int lb_port = test::free_port(), lb_http_port = test::free_port();
  std::vector<std::string> http_addresses;
  for (const auto& r : replicas_) http_addresses.push_back(http ? r->http_address() : r->address());
  std::ofstream(dir_ / "nginx.conf") << nginx_conf(dir_, lb_port, lb_http_port, addresses_, http_addresses);
  nginx_ = std::make_unique<ChildProcess>(
      std::vector<std::string>{fs::exists("/usr/sbin/nginx") ? "/usr/sbin/nginx" : "nginx", "-p", dir_.string(), "-e",
                               (dir_ / "nginx-error.log").string(), "-c", (dir_ / "nginx.conf").string(), "-g",
                               "daemon off;"},
      (dir_ / "nginx.log").string());
  nginx_->wait_for_port(lb_port, 20);
  nginx_->wait_for_port(lb_http_port, 20);
  lb_ = "127.0.0.1:" + std::to_string(lb_port);
  lb_http_ = "127.0.0.1:" + std::to_string(lb_http_port);
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
void Cluster::pause(int i) { replicas_[i]->pause(); }
void Cluster::resume(int i) { replicas_[i]->resume(); }
int Cluster::terminate(int i) { return replicas_[i]->terminate(); }
void Cluster::stop_redis() { redis_.reset(); }

}  // namespace filigree::test
