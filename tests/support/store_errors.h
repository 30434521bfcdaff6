#pragma once
// Helpers of the Redis tests (auth, TLS): made-up passwords and the message
// a store call fails with.

#include <random>
#include <string>

#include <gtest/gtest.h>

#include "server/state/session_store.h"

namespace filigree::test {

// 32 hex digits from the system's random source: a password no fixture ships.
inline std::string random_password() {
  std::random_device random;
  std::string s;
  for (int i = 0; i < 32; ++i) s += "0123456789abcdef"[random() % 16];
  return s;
}

// The message of the StoreUnavailable that `f` throws ("" and a test failure if none).
template <typename F>
std::string store_error(F f) {
  try {
    f();
  } catch (const server::StoreUnavailable& e) {
    return e.what();
  }
  ADD_FAILURE() << "no StoreUnavailable";
  return "";
}

}  // namespace filigree::test
