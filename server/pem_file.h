#pragma once
// A PEM file read whole for the TLS options (--tls-cert, --tls-key,
// --tls-client-ca): checked here so that a wrong path or file fails at once
// with the option's name, rather than later as a generic TLS error.

#include <fstream>
#include <sstream>
#include <stdexcept>
#include <string>

namespace filigree::server {

// The file's text (read at once, so a reload sees one version of it).
// Throws std::runtime_error naming `option` and the path if it cannot be read
// or holds no PEM block.
inline std::string read_pem(const std::string& path, const char* option) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw std::runtime_error(std::string(option) + " " + path + " cannot be read");
  std::ostringstream text;
  text << in.rdbuf();
  if (!in.good() && !in.eof()) throw std::runtime_error(std::string(option) + " " + path + " cannot be read");
  std::string out = std::move(text).str();
  // Said apart: a renewal that truncates before it writes leaves an empty file.
  if (out.empty()) throw std::runtime_error(std::string(option) + " " + path + " is empty");
  if (out.find("-----BEGIN ") == std::string::npos)
    throw std::runtime_error(std::string(option) + " " + path + " holds no PEM block");
  return out;
}

}  // namespace filigree::server
