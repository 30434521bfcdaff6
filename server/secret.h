#pragma once
// Session secrets: made from the OS's randomness, compared in constant time.

#include <string>
#include <string_view>

namespace filigree::server {

// 128 random bits from the OS (getrandom(2)) as 32 lowercase hex digits.
// Throws std::system_error if the OS cannot give them.
std::string random_token();

// Whether `given` equals `secret`, taking the same time whichever byte
// differs (OpenSSL's CRYPTO_memcmp), so a client cannot find a token byte by
// byte by timing refusals. Only the lengths may show (tokens have one length).
bool same_secret(std::string_view given, std::string_view secret);

}  // namespace filigree::server
