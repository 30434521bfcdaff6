#pragma once
// The value of one hexadecimal digit (either case), -1 for another
// character: for percent-decoding a URL's path and query.

namespace filigree::server::http {

inline int hex_value(char c) {
  if (c >= '0' && c <= '9') return c - '0';
  if (c >= 'a' && c <= 'f') return c - 'a' + 10;
  if (c >= 'A' && c <= 'F') return c - 'A' + 10;
  return -1;
}

}  // namespace filigree::server::http
