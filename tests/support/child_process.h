#pragma once
// A helper program (redis-server, nginx) run by a test as a child process,
// its output in a log file; stopped (SIGTERM, then waited for) when the
// object goes away.

#include <string>
#include <vector>

namespace filigree::test {

class ChildProcess {
 public:
  // Starts argv[0] (looked up in PATH) with `argv`, stdout and stderr to `log_file`.
  ChildProcess(std::vector<std::string> argv, const std::string& log_file);
  ~ChildProcess();
  ChildProcess(const ChildProcess&) = delete;
  ChildProcess& operator=(const ChildProcess&) = delete;

  // Waits until 127.0.0.1:`port` accepts connections; throws with the log's
  // tail if the process exits first or `seconds` pass.
  void wait_for_port(int port, double seconds) const;

 private:
  int pid_ = -1;
  std::string log_file_;
};

// A TCP port on 127.0.0.1 that was free a moment ago (for programs that
// cannot pick their own and report it).
int free_port();


}  // namespace filigree::test
