#pragma once
// A plain TCP client on blocking POSIX sockets with poll() deadlines, for
// tests that must misbehave (send a header a byte at a time, stop mid-body,
// hold a connection idle) and observe when the server closes on them. Every
// wait has a deadline, so a test fails rather than hangs. Also the smallest
// HTTP/1.1 response reader that those tests need.

#include <chrono>
#include <functional>
#include <map>
#include <optional>
#include <string>
#include <string_view>

namespace filigree::test {

using Clock = std::chrono::steady_clock;

class RawSocket {
 public:
  // Connects to HOST:PORT (a numeric IPv4 host). Throws std::runtime_error if it cannot.
  explicit RawSocket(const std::string& address);
  ~RawSocket();
  RawSocket(const RawSocket&) = delete;
  RawSocket& operator=(const RawSocket&) = delete;

  // All of `bytes`; false once the connection is broken (never SIGPIPE).
  // Safe from another thread than the one reading.
  bool send(std::string_view bytes);

  // Reads until `done(received())` holds (true), or the connection ends or
  // `deadline` passes first (false).
  bool read_until(const std::function<bool(const std::string&)>& done, Clock::time_point deadline);

  // Reads until the server closes the connection (EOF or reset): true, with
  // when it was seen in closed_at(); false if `deadline` passed first.
  bool read_until_closed(Clock::time_point deadline);

  // Everything read so far that the caller has not taken away.
  std::string& received() { return received_; }
  Clock::time_point closed_at() const { return closed_at_; }
  bool closed() const { return closed_; }
  // Our side goes away now (the server sees EOF).
  void close();

 private:
  // One poll() and read; false once the connection has ended or the deadline passed.
  bool read_some(Clock::time_point deadline);

  int fd_ = -1;
  std::string received_;
  bool closed_ = false;
  Clock::time_point closed_at_{};
};

struct HttpResponse {
  int status = 0;
  std::map<std::string, std::string> headers;  // names lower case
  std::string body;
  // The response keeps the connection open (HTTP/1.1 without Connection: close).
  bool keep_alive() const;
};

// Takes one whole response off the front of `bytes`, if it is all there
// (bodies with Content-Length, or none).
std::optional<HttpResponse> take_response(std::string& bytes);

// Reads one response on `socket` (nullopt: the connection ended or the deadline passed first).
std::optional<HttpResponse> read_response(RawSocket& socket, Clock::time_point deadline);

}  // namespace filigree::test
