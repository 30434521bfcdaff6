#pragma once
// Whether a certificate chain and private key (PEM) may be put in force on a
// TLS port: both parse, the key is the leaf certificate's, every certificate
// is within its validity period, the key is strong enough and no
// certificate is signed with a broken digest. Checked before gRPC or OpenSSL
// see a pair, at start and at every re-read: a pair that fails here would
// only fail every handshake later (or, for gRPC 1.51's file watcher, abort
// the process), with nothing said to the operator.
//
// One checker for the gRPC port (verified_tls_files.h) and HTTPS on --http
// (http/tls_context.h), so that both ports accept and refuse the same files.

#include <ctime>
#include <stdexcept>
#include <string>
#include <string_view>

namespace filigree::server {

// Keys below this security strength (NIST SP 800-57: RSA < 2048 bits, EC
// below P-224) are refused.
inline constexpr int kMinimumSecurityBits = 112;

// What is wrong with a pair. The message says what and why in words an
// operator can act on; it names no file and quotes no byte of the key.
class TlsPairError : public std::runtime_error {
 public:
  // Which of the two the problem is in: the operator fixes that file.
  enum class Part { kChain, kKey, kPair };
  TlsPairError(Part part, const std::string& message) : std::runtime_error(message), part_(part) {}
  Part part() const { return part_; }

 private:
  Part part_;
};

// What was put in force, for the log line that says so.
struct TlsPairSummary {
  std::string subject;    // the leaf's subject, one line ("/CN=…")
  std::string not_after;  // when the leaf expires ("Nov 28 00:15:38 2026 GMT")
  std::string key;        // "EC 256 bits", "RSA 2048 bits"
};

// Checks the pair at time `now`. Throws TlsPairError when it must not be used.
TlsPairSummary check_tls_pair(std::string_view chain_pem, std::string_view key_pem, std::time_t now = std::time(nullptr));

// A CA bundle (client or peer CAs): at least one certificate, and every PEM
// block in it one. Returns how many. Throws std::runtime_error (no file named).
std::size_t check_ca_bundle(std::string_view pem);

// A pair read from its files and checked, the key to be wiped after use.
struct CheckedTlsPair {
  std::string chain_pem;
  std::string key_pem;  // cleansed by the destructor
  TlsPairSummary summary;
  CheckedTlsPair() = default;
  CheckedTlsPair(CheckedTlsPair&&) = default;
  CheckedTlsPair& operator=(CheckedTlsPair&&) = default;
  ~CheckedTlsPair();
};

// Reads --tls-cert `cert_path` and --tls-key `key_path` and checks them.
// Throws std::runtime_error naming the option and the file at fault (not
// their contents) and what is wrong.
CheckedTlsPair read_checked_tls_pair(const std::string& cert_path, const std::string& key_path);

}  // namespace filigree::server
