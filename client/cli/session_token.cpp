#include "cli/session_token.h"

#include <cctype>
#include <cstdlib>
#include <fstream>
#include <stdexcept>

namespace filigree::cli {

std::string read_session_token(const std::string& file, const char* option, const char* env) {
  std::string token;
  if (!file.empty()) {
    std::ifstream in(file);
    if (!in || !std::getline(in, token)) throw std::runtime_error("cannot read a token from " + file);
  } else if (const char* value = std::getenv(env)) {
    token = value;
  }
  while (!token.empty() && std::isspace(static_cast<unsigned char>(token.back()))) token.pop_back();
  if (token.empty())
    throw std::runtime_error(std::string("no session token: set ") + env + " or give " + option +
                             " FILE (never on the command line)");
  return token;
}

}  // namespace filigree::cli
