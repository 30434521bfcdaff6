#include "support/server_process.h"

#include <cerrno>
#include <csignal>
#include <cstdio>
#include <stdexcept>

#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

namespace filigree::test {

namespace {

// Blocking read of one line (without the newline); stops at EOF.
std::string read_line(int fd) {
  std::string line;
  char c;
  while (read(fd, &c, 1) == 1 && c != '\n') line += c;
  return line;
}

}  // namespace

ServerProcess::ServerProcess(const std::string& binary, const std::vector<std::string>& args, bool http,
                             unsigned open_files) {
  int out[2];
  if (pipe(out) != 0) throw std::runtime_error("pipe failed");
  pid_ = fork();
  if (pid_ < 0) throw std::runtime_error("fork failed");
  if (pid_ == 0) {
    dup2(out[1], STDOUT_FILENO);
    close(out[0]);
    close(out[1]);
    if (open_files != 0) {
      const rlimit limit{open_files, open_files};
      if (setrlimit(RLIMIT_NOFILE, &limit) != 0) _exit(126);
    }
    std::vector<std::string> all = {binary, "--listen", "127.0.0.1:0", "--log-level", "warn"};
    if (http) all.insert(all.end(), {"--http", "127.0.0.1:0"});
    all.insert(all.end(), args.begin(), args.end());
    std::vector<char*> argv;
    for (auto& a : all) argv.push_back(a.data());
    argv.push_back(nullptr);
    execv(binary.c_str(), argv.data());
    _exit(127);
  }
  close(out[1]);
  // Blocking read of the first line: the server prints it once it listens.
  const std::string line = read_line(out[0]);
  // With --http, the second line follows at once.
  const std::string http_line = http ? read_line(out[0]) : std::string();
  close(out[0]);
  const std::string prefix = "listening on ", http_prefix = "http on ";
  if (line.rfind(prefix, 0) != 0 || (http && http_line.rfind(http_prefix, 0) != 0)) {
    terminate();
    throw std::runtime_error("filigree-server did not start: '" + line + "' '" + http_line + "'");
  }
  address_ = line.substr(prefix.size());
  if (http) http_address_ = http_line.substr(http_prefix.size());
}

ServerProcess::~ServerProcess() {
  if (pid_ > 0) {
    kill(pid_, SIGKILL);
    waitpid(pid_, nullptr, 0);
  }
}

void ServerProcess::kill_now() {
  if (pid_ <= 0) return;
  kill(pid_, SIGKILL);
  waitpid(pid_, nullptr, 0);
  pid_ = -1;
}

void ServerProcess::pause() { signal_and_wait(SIGSTOP, WUNTRACED); }

void ServerProcess::resume() { signal_and_wait(SIGCONT, WCONTINUED); }

void ServerProcess::signal_and_wait(int signal, int wait_for) {
  if (pid_ <= 0) return;
  kill(pid_, signal);
  // kill() only sends it: wait until the process has stopped or continued (or
  // ended), so that nothing it does after this call is a race with the signal.
  int status = 0;
  while (waitpid(pid_, &status, wait_for) < 0 && errno == EINTR) {
  }
  if (WIFEXITED(status) || WIFSIGNALED(status)) pid_ = -1;  // it ended instead (reaped now)
}

int ServerProcess::terminate() {
  if (pid_ <= 0) return -1;
  kill(pid_, SIGTERM);
  int status = 0;
  waitpid(pid_, &status, 0);
  pid_ = -1;
  return WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
}

}  // namespace filigree::test
