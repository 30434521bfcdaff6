#pragma once
// The gRPC port's front door: accepts its TCP connections itself and relays
// each, byte for byte (TLS included), to gRPC listening on a private unix
// socket. gRPC 1.51 stops accepting for good once accept4() fails with
// EMFILE, and has no cap on connections; here
//   - at most `max_connections` are relayed at once: further ones are
//     accepted and closed at once (the client sees a closed connection, and
//     retries), so a flood cannot use up the process's descriptors;
//   - when descriptors run out anyway (EMFILE/ENFILE), a spare one kept for
//     that is closed to accept and close the waiting connection, then taken
//     again: accepting goes on, and works again as soon as descriptors free.
// A relayed connection costs three descriptors (the client's socket, the
// relay's unix socket, and gRPC's end of it).

#include <cstddef>
#include <filesystem>
#include <memory>
#include <string>

namespace filigree::server {

struct ConnectionGuardOptions {
  std::string listen;                    // HOST:PORT (port 0: a free one)
  std::filesystem::path upstream;        // gRPC's unix socket
  std::size_t max_connections = 1024;    // relayed at once
};

class ConnectionGuard {
 public:
  // Binds and listens (throws std::runtime_error saying why it cannot);
  // accepts once start() is called.
  explicit ConnectionGuard(ConnectionGuardOptions options);
  ~ConnectionGuard();
  ConnectionGuard(const ConnectionGuard&) = delete;
  ConnectionGuard& operator=(const ConnectionGuard&) = delete;

  // The bound port (the one chosen for port 0).
  int port() const;
  // Starts accepting and relaying on a thread of its own (one thread: a
  // relay's sockets are never used from two threads at once).
  void start();
  // Stops accepting and closes every relayed connection; joins the thread.
  void stop();
  // Connections relayed now.
  std::size_t connections() const;

 private:
  struct State;
  std::shared_ptr<State> state_;
};

// A folder only this user may enter (mkdtemp: 0700) for the unix socket gRPC
// listens on behind the guard, so no other user can reach gRPC around it;
// removed with what is in it when this goes. Throws std::runtime_error.
class PrivateSocketDir {
 public:
  PrivateSocketDir();
  ~PrivateSocketDir();
  PrivateSocketDir(const PrivateSocketDir&) = delete;
  PrivateSocketDir& operator=(const PrivateSocketDir&) = delete;
  std::filesystem::path socket() const { return dir_ / "grpc.sock"; }

 private:
  std::filesystem::path dir_;
};

// The descriptor budget of this process for the gRPC port: raises the soft
// limit on open files to the hard one, and returns how many connections may
// be relayed so that `reserved` descriptors stay for everything else (files,
// the browser port's connections, gRPC's own).
std::size_t connection_budget(std::size_t reserved);

}  // namespace filigree::server
