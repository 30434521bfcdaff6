#include "support/server_run.h"

#include <csignal>
#include <stdexcept>
#include <string_view>

#include <fcntl.h>
#include <sys/wait.h>
#include <unistd.h>

namespace filigree::test {

ServerRun run_server(const std::string& binary, const std::vector<std::string>& args,
                     const std::vector<std::string>& env) {
  std::vector<std::string> argv{binary, "--listen", "127.0.0.1:0", "--log-level", "info"};
  argv.insert(argv.end(), args.begin(), args.end());
  std::vector<std::string> environment = env;
  for (char** e = environ; *e; ++e)
    if (std::string_view(*e).rfind("FILIGREE_REDIS_PASSWORD=", 0) != 0) environment.emplace_back(*e);
  // Built before fork: the child only dups and execs (this process may have gRPC threads).
  std::vector<char*> argv_c, env_c;
  for (auto& a : argv) argv_c.push_back(a.data());
  for (auto& e : environment) env_c.push_back(e.data());
  argv_c.push_back(nullptr);
  env_c.push_back(nullptr);
  int out[2];
  if (pipe2(out, O_CLOEXEC) != 0) throw std::runtime_error("pipe failed");
  const pid_t pid = fork();
  if (pid < 0) throw std::runtime_error("fork failed");
  if (pid == 0) {
    dup2(out[1], STDOUT_FILENO);
    dup2(out[1], STDERR_FILENO);
    execve(argv_c[0], argv_c.data(), env_c.data());
    _exit(127);
  }
  close(out[1]);
  ServerRun run;
  std::string line;
  char c;
  while (read(out[0], &c, 1) == 1) {
    run.output += c;
    if (c != '\n') {
      line += c;
      continue;
    }
    if (!run.listened && line.rfind("listening on ", 0) == 0) {
      run.listened = true;
      kill(pid, SIGTERM);  // then read on to EOF: the shutdown's log lines too
    }
    line.clear();
  }
  close(out[0]);
  int status = 0;
  waitpid(pid, &status, 0);
  run.status = WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
  return run;
}

}  // namespace filigree::test
