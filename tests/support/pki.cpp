#include "support/pki.h"

#include <fcntl.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <fstream>
#include <iterator>
#include <stdexcept>
#include <vector>

extern char** environ;

namespace filigree::test {
namespace {

namespace fs = std::filesystem;

// Runs the openssl command with `args` in `dir`, its output to openssl.log
// there; throws with that log if it fails.
void openssl(const fs::path& dir, std::vector<std::string> args) {
  args.insert(args.begin(), "openssl");
  std::vector<char*> argv;
  for (auto& a : args) argv.push_back(a.data());
  argv.push_back(nullptr);
  const std::string log = (dir / "openssl.log").string();
  posix_spawn_file_actions_t actions;
  posix_spawn_file_actions_init(&actions);
  posix_spawn_file_actions_addopen(&actions, STDOUT_FILENO, log.c_str(), O_WRONLY | O_CREAT | O_APPEND, 0600);
  posix_spawn_file_actions_adddup2(&actions, STDOUT_FILENO, STDERR_FILENO);
  posix_spawn_file_actions_addchdir_np(&actions, dir.c_str());
  pid_t pid = 0;
  const int rc = posix_spawnp(&pid, "openssl", &actions, nullptr, argv.data(), environ);
  posix_spawn_file_actions_destroy(&actions);
  if (rc != 0) throw std::runtime_error("cannot run openssl");
  int status = 0;
  waitpid(pid, &status, 0);
  if (!WIFEXITED(status) || WEXITSTATUS(status) != 0) {
    std::ifstream in(log);
    throw std::runtime_error("openssl " + args[1] + " failed:\n" + std::string(std::istreambuf_iterator<char>(in), {}));
  }
}

}  // namespace

Pki::Pki(fs::path dir) : dir_(std::move(dir)) { fs::create_directories(dir_); }

void Pki::ca(const std::string& name) {
  openssl(dir_, {"req", "-x509", "-newkey", "ec", "-pkeyopt", "ec_paramgen_curve:P-256", "-nodes", "-days", "1", "-keyout",
                 name + ".key", "-out", name + ".pem", "-subj", "/CN=filigree test " + name, "-addext",
                 "basicConstraints=critical,CA:TRUE", "-addext", "keyUsage=critical,keyCertSign,cRLSign"});
}

void Pki::issue(const std::string& name, const std::string& ca, const std::string& extensions, long serial,
                const CertOptions& options) {
  std::vector<std::string> request = {"req", "-newkey"};
  if (options.key == "ec")
    request.insert(request.end(), {"ec", "-pkeyopt", "ec_paramgen_curve:P-256"});
  else
    request.push_back(options.key);
  request.insert(request.end(), {"-nodes", "-keyout", name + ".key", "-out", name + ".csr", "-subj", "/CN=" + name});
  openssl(dir_, request);
  reissue(name, name, ca, extensions, serial, options);
}

void Pki::reissue(const std::string& name, const std::string& of, const std::string& ca, const std::string& extensions,
                  long serial, const CertOptions& options) {
  std::ofstream(dir_ / (name + ".ext")) << extensions << "\n";
  std::vector<std::string> sign = {"x509", "-req", "-in", of + ".csr", "-CA", ca + ".pem", "-CAkey", ca + ".key", "-days",
                                   std::to_string(options.days), "-out", name + ".pem", "-extfile", name + ".ext"};
  if (!options.digest.empty()) sign.push_back("-" + options.digest);
  if (serial != 0) {
    sign.insert(sign.end(), {"-set_serial", std::to_string(serial)});
  } else {
    sign.push_back("-CAcreateserial");
  }
  openssl(dir_, sign);
}

}  // namespace filigree::test
