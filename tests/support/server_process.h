#pragma once
// Runs filigree-server as a child process on 127.0.0.1 with an ephemeral
// port, for end-to-end tests: started by the test, stopped by it.

#include <string>
#include <vector>

namespace filigree::test {

class ServerProcess {
 public:
  // Starts `binary --listen 127.0.0.1:0 <args>` and waits for its
  // "listening on HOST:PORT" line. Throws std::runtime_error if it exits first.
  // With `http`, also passes `--http 127.0.0.1:0` and waits for the
  // "http on HOST:PORT" line that follows.
  // `open_files`: the child's limit on open files (RLIMIT_NOFILE, soft and
  // hard); 0 keeps this process's.
  ServerProcess(const std::string& binary, const std::vector<std::string>& args, bool http = false, unsigned open_files = 0);
  // Kills the server (SIGKILL) if it is still running.
  ~ServerProcess();
  ServerProcess(const ServerProcess&) = delete;
  ServerProcess& operator=(const ServerProcess&) = delete;

  const std::string& address() const { return address_; }
  // The HTTP (web viewer, gRPC-Web) address; empty unless started with `http`.
  const std::string& http_address() const { return http_address_; }
  // Sends SIGTERM and waits; returns the exit status (0 for a clean drain).
  int terminate();
  // Sends SIGKILL and waits: the process dies without a chance to clean up.
  void kill_now();
  bool running() const { return pid_ > 0; }
  int pid() const { return pid_; }
  // SIGSTOP / SIGCONT: the process freezes (a long pause, a partition) and comes back.
  void pause();
  void resume();

 private:
  void signal_and_wait(int signal, int wait_for);
  int pid_ = -1;
  std::string address_;
  std::string http_address_;
};

}  // namespace filigree::test
