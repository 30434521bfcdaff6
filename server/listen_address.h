#pragma once
// What a --listen or --http address exposes: the loopback interface only, or
// the network (so plaintext there needs the operator's explicit --insecure).

#include <string>

namespace filigree::server {

// True for HOST:PORT whose host is 127.0.0.0/8, ::1 ([::1]) or localhost, and
// for unix: sockets; false for anything else (0.0.0.0, [::], a name, an
// empty host), which other machines may reach.
bool is_loopback_only(const std::string& address);

}  // namespace filigree::server
