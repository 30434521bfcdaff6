#include "server/tls_pair_check.h"

#include <memory>
#include <vector>

#include <openssl/bio.h>
#include <openssl/crypto.h>
#include <openssl/err.h>
#include <openssl/evp.h>
#include <openssl/objects.h>
#include <openssl/pem.h>
#include <openssl/x509.h>
#include <openssl/x509v3.h>

#include "server/pem_file.h"

namespace filigree::server {
namespace {

struct BioFree {
  void operator()(BIO* b) const { BIO_free(b); }
};
struct X509Free {
  void operator()(X509* x) const { X509_free(x); }
};
struct PkeyFree {
  void operator()(EVP_PKEY* k) const { EVP_PKEY_free(k); }
};
using Bio = std::unique_ptr<BIO, BioFree>;
using Cert = std::unique_ptr<X509, X509Free>;
using Pkey = std::unique_ptr<EVP_PKEY, PkeyFree>;

// Leaves OpenSSL's error queue empty however a check ends, so that a later,
// unrelated OpenSSL call on this thread does not report our errors.
struct ClearErrors {
  ~ClearErrors() { ERR_clear_error(); }
};

Bio memory_bio(std::string_view pem) {
  Bio bio(BIO_new_mem_buf(pem.data(), static_cast<int>(pem.size())));
  if (!bio) throw std::bad_alloc();
  return bio;
}

// Subjects come from the file: bounded, so that a message stays short
// whatever the certificate holds.
std::string subject_of(X509* cert) {
  char line[256] = {};
  X509_NAME_oneline(X509_get_subject_name(cert), line, sizeof line - 1);
  return line;
}

std::string time_text(const ASN1_TIME* t) {
  Bio bio(BIO_new(BIO_s_mem()));
  if (!bio || ASN1_TIME_print(bio.get(), t) != 1) return "(unreadable time)";
  char* data = nullptr;
  const long n = BIO_get_mem_data(bio.get(), &data);
  return std::string(data, static_cast<std::size_t>(n));
}

// "the certificate /CN=x" for the leaf, "certificate 2 of the chain (/CN=y)" after it.
std::string which(std::size_t index, X509* cert) {
  if (index == 0) return "the certificate " + subject_of(cert);
  return "certificate " + std::to_string(index + 1) + " of the chain (" + subject_of(cert) + ")";
}

std::string key_text(EVP_PKEY* key) {
  const char* type = EVP_PKEY_get0_type_name(key);
  return std::string(type ? type : "unknown") + " " + std::to_string(EVP_PKEY_get_bits(key)) + " bits";
}

std::vector<Cert> read_certificates(std::string_view pem, bool* malformed) {
  Bio bio = memory_bio(pem);
  std::vector<Cert> out;
  while (X509* cert = PEM_read_bio_X509(bio.get(), nullptr, nullptr, nullptr)) out.emplace_back(cert);
  // The end of the text reads as "no start line"; anything else is a block
  // that claims to be a certificate and is not one.
  const unsigned long err = ERR_peek_last_error();
  *malformed = err != 0 && !(ERR_GET_LIB(err) == ERR_LIB_PEM && ERR_GET_REASON(err) == PEM_R_NO_START_LINE);
  ERR_clear_error();
  return out;
}

// Digests whose collisions can be bought: a certificate signed with one can be forged.
bool broken_digest(int nid) {
  return nid == NID_sha1 || nid == NID_md5 || nid == NID_md5_sha1 || nid == NID_md4 || nid == NID_md2;
}

bool self_signed(X509* cert) { return X509_check_issued(cert, cert) == X509_V_OK; }

// No passphrase can be given to a server that restarts by itself.
int no_passphrase(char*, int, int, void*) { return -1; }

}  // namespace

CheckedTlsPair::~CheckedTlsPair() { OPENSSL_cleanse(key_pem.data(), key_pem.size()); }

TlsPairSummary check_tls_pair(std::string_view chain_pem, std::string_view key_pem, std::time_t now) {
  const ClearErrors clear;
  using Part = TlsPairError::Part;

  bool malformed = false;
  const std::vector<Cert> chain = read_certificates(chain_pem, &malformed);
  if (malformed) throw TlsPairError(Part::kChain, "holds a CERTIFICATE block that does not parse (damaged or truncated)");
  if (chain.empty()) throw TlsPairError(Part::kChain, "holds no certificate (a PEM block BEGIN CERTIFICATE)");

  Bio key_bio = memory_bio(key_pem);
  const Pkey key(PEM_read_bio_PrivateKey(key_bio.get(), nullptr, no_passphrase, nullptr));
  if (!key) {
    if (key_pem.find("ENCRYPTED") != std::string_view::npos)
      throw TlsPairError(Part::kKey, "holds an encrypted private key: give it unencrypted (mode 0600), no passphrase can be asked for");
    if (key_pem.find("PRIVATE KEY-----") == std::string_view::npos)
      throw TlsPairError(Part::kKey, "holds no private key (PEM)");
    throw TlsPairError(Part::kKey, "holds a private key that does not parse (damaged or truncated)");
  }

  X509* leaf = chain.front().get();
  if (X509_check_private_key(leaf, key.get()) != 1)
    throw TlsPairError(Part::kPair, "is not the key of " + which(0, leaf));

  for (std::size_t i = 0; i < chain.size(); ++i) {
    X509* cert = chain[i].get();
    const ASN1_TIME* not_before = X509_get0_notBefore(cert);
    const ASN1_TIME* not_after = X509_get0_notAfter(cert);
    const int before = X509_cmp_time(not_before, &now), after = X509_cmp_time(not_after, &now);
    if (before == 0 || after == 0) throw TlsPairError(Part::kChain, which(i, cert) + " has an unreadable validity period");
    if (before > 0)
      throw TlsPairError(Part::kChain, which(i, cert) + " is not valid before " + time_text(not_before) +
                                           " (check this machine's clock)");
    if (after < 0) throw TlsPairError(Part::kChain, which(i, cert) + " expired on " + time_text(not_after));

    EVP_PKEY* public_key = X509_get0_pubkey(cert);
    if (!public_key) throw TlsPairError(Part::kChain, which(i, cert) + " has a public key that does not parse");
    if (EVP_PKEY_get_security_bits(public_key) < kMinimumSecurityBits)
      throw TlsPairError(Part::kChain, which(i, cert) + " has a weak key (" + key_text(public_key) +
                                           "): at least RSA 2048 bits or EC P-256 is needed");

    // A trust anchor's own signature is never checked by clients; every
    // other signature is what a client relies on.
    if (i > 0 && self_signed(cert)) continue;
    int digest = NID_undef, secbits = 0;
    std::uint32_t flags = 0;
    if (X509_get_signature_info(cert, &digest, nullptr, &secbits, &flags) != 1)
      throw TlsPairError(Part::kChain, which(i, cert) + " has a signature algorithm OpenSSL does not know");
    if (broken_digest(digest) || ((flags & X509_SIG_INFO_VALID) && secbits > 0 && secbits < kMinimumSecurityBits)) {
      const char* name = OBJ_nid2sn(digest);
      throw TlsPairError(Part::kChain, which(i, cert) + " is signed with " + (name ? name : "a weak digest") +
                                           ", which can be forged: have it signed with SHA-256 or better");
    }
  }
  return {subject_of(leaf), time_text(X509_get0_notAfter(leaf)), key_text(key.get())};
}

std::size_t check_ca_bundle(std::string_view pem) {
  const ClearErrors clear;
  bool malformed = false;
  const std::vector<Cert> certs = read_certificates(pem, &malformed);
  if (malformed) throw std::runtime_error("holds a CERTIFICATE block that does not parse (damaged or truncated)");
  if (certs.empty()) throw std::runtime_error("holds no certificate");
  return certs.size();
}

CheckedTlsPair read_checked_tls_pair(const std::string& cert_path, const std::string& key_path) {
  if (cert_path.empty() || key_path.empty()) throw std::runtime_error("--tls-cert and --tls-key go together");
  CheckedTlsPair pair;
  pair.chain_pem = read_pem(cert_path, "--tls-cert");
  pair.key_pem = read_pem(key_path, "--tls-key");
  try {
    pair.summary = check_tls_pair(pair.chain_pem, pair.key_pem);
  } catch (const TlsPairError& e) {
    switch (e.part()) {
      case TlsPairError::Part::kChain: throw std::runtime_error("--tls-cert " + cert_path + ": " + e.what());
      case TlsPairError::Part::kKey: throw std::runtime_error("--tls-key " + key_path + ": " + e.what());
      case TlsPairError::Part::kPair:
        throw std::runtime_error("--tls-key " + key_path + " " + e.what() + " in --tls-cert " + cert_path +
                                 " (a renewal half done? install the key and certificate together)");
    }
    throw;
  }
  return pair;
}

}  // namespace filigree::server
