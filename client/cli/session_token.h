#pragma once
// Session tokens for the CLI's client commands: from a file or the
// environment, never from the command line (which every user of the
// machine can read, with ps) and never printed.

#include <string>

namespace filigree::cli {

// The first line of `file` (trailing whitespace dropped) when `file` is not
// empty, else the environment variable `env`. Throws std::runtime_error
// naming `option` (the file's option) and `env` when neither gives one.
std::string read_session_token(const std::string& file, const char* option, const char* env);

}  // namespace filigree::cli
