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

// How `issue` makes a certificate; the defaults are a sound one.
struct CertOptions {
  std::string key = "ec";  // "ec" (P-256) or an openssl -newkey argument such as "rsa:1024"
  std::string digest;      // the signature's digest ("sha1"); empty: openssl's default (SHA-256)
  int days = 1;            // validity from now; negative: expired that many days ago
};

class Pki {
 public:
  // Creates `dir` if needed; files go there.
  explicit Pki(std::filesystem::path dir);

  // NAME.pem and NAME.key: a self-signed CA.
  void ca(const std::string& name);
  // NAME.pem and NAME.key: a certificate signed by CA `ca`, with the x509v3
  // `extensions` (lines of an openssl extfile), serial `serial` (0: random).
  void issue(const std::string& name, const std::string& ca, const std::string& extensions, long serial = 0,
             const CertOptions& options = {});
  // NAME.pem only: another certificate for the key of `of` (made by issue),
  // signed by CA `ca` with `options` (days, digest; the key is `of`'s).
  void reissue(const std::string& name, const std::string& of, const std::string& ca, const std::string& extensions,
               long serial, const CertOptions& options);

  std::filesystem::path operator/(const std::string& file) const { return dir_ / file; }
  const std::filesystem::path& dir() const { return dir_; }

 private:
  std::filesystem::path dir_;
};

}  // namespace filigree::test
