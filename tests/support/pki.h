#pragma once
// A throwaway PKI for TLS tests, made at run time with the openssl command
// (EC P-256 keys: fast) in a directory the caller owns: no key ships.

#include <filesystem>
#include <string>

namespace filigree::test {

// Extensions of a server certificate for loopback (as `issue` takes them).
inline constexpr char kLoopbackServer[] = "subjectAltName=DNS:localhost,IP:127.0.0.1\nextendedKeyUsage=serverAuth";
// A client certificate.
inline constexpr char kClient[] = "extendedKeyUsage=clientAuth";

class Pki {
 public:
  // Creates `dir` if needed; files go there.
  explicit Pki(std::filesystem::path dir);

  // NAME.pem and NAME.key: a self-signed CA.
  void ca(const std::string& name);
  // NAME.pem and NAME.key: a certificate signed by CA `ca`, with the x509v3
  // `extensions` (lines of an openssl extfile), serial `serial` (0: random).
  void issue(const std::string& name, const std::string& ca, const std::string& extensions, long serial = 0);

  std::filesystem::path operator/(const std::string& file) const { return dir_ / file; }
  const std::filesystem::path& dir() const { return dir_; }

 private:
  std::filesystem::path dir_;
};

}  // namespace filigree::test
