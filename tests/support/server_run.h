#pragma once
// One run of filigree-server for tests of how it starts: it listened (and was
// then stopped with SIGTERM), or it exited by itself; its output either way,
// to check what it logged (and what it must never log).

#include <string>
#include <vector>

namespace filigree::test {

struct ServerRun {
  bool listened = false;
  int status = -1;     // exit status; 128 + signal if killed
  std::string output;  // stdout and stderr
};

// Runs `binary --listen 127.0.0.1:0 --log-level info <args>` with `env`
// ("NAME=VALUE") added to this environment minus FILIGREE_REDIS_PASSWORD.
// Reads its output until it listens or exits (EOF): it waits on lines, not on time.
ServerRun run_server(const std::string& binary, const std::vector<std::string>& args,
                     const std::vector<std::string>& env = {});

}  // namespace filigree::test
