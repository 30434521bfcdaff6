#include "support/raw_socket.h"

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <cstring>
#include <stdexcept>

#include <arpa/inet.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

namespace filigree::test {

RawSocket::RawSocket(const std::string& address) {
  const auto colon = address.rfind(':');
  if (colon == std::string::npos) throw std::runtime_error("want HOST:PORT, got " + address);
  sockaddr_in to{};
  to.sin_family = AF_INET;
  to.sin_port = htons(static_cast<std::uint16_t>(std::stoi(address.substr(colon + 1))));
  if (::inet_pton(AF_INET, address.substr(0, colon).c_str(), &to.sin_addr) != 1)
    throw std::runtime_error("not an IPv4 address: " + address);
  fd_ = ::socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
  if (fd_ < 0) throw std::runtime_error(std::string("socket: ") + std::strerror(errno));
  if (::connect(fd_, reinterpret_cast<const sockaddr*>(&to), sizeof to) != 0) {
    const int e = errno;
    ::close(fd_);
    fd_ = -1;
    throw std::runtime_error("connect to " + address + ": " + std::strerror(e));
  }
  const int one = 1;
  ::setsockopt(fd_, IPPROTO_TCP, TCP_NODELAY, &one, sizeof one);  // a trickled byte goes out alone
}

RawSocket::~RawSocket() { close(); }

void RawSocket::close() {
  if (fd_ >= 0) ::close(fd_);
  fd_ = -1;
}

bool RawSocket::send(std::string_view bytes) {
  while (!bytes.empty()) {
    const ssize_t n = ::send(fd_, bytes.data(), bytes.size(), MSG_NOSIGNAL);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) return false;
    bytes.remove_prefix(static_cast<std::size_t>(n));
  }
  return true;
}

bool RawSocket::read_some(Clock::time_point deadline) {
  if (closed_ || fd_ < 0) return false;
  const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(deadline - Clock::now()).count();
  if (left <= 0) return false;
  pollfd p{fd_, POLLIN, 0};
  const int ready = ::poll(&p, 1, static_cast<int>(std::min<long long>(left, 60'000)));
  if (ready < 0 && errno == EINTR) return true;
  if (ready <= 0) return Clock::now() < deadline;
  char buf[4096];
  const ssize_t n = ::recv(fd_, buf, sizeof buf, 0);
  if (n < 0 && errno == EINTR) return true;
  if (n <= 0) {  // EOF, or a reset: either way the server has closed
    closed_ = true;
    closed_at_ = Clock::now();
    return false;
  }
  received_.append(buf, static_cast<std::size_t>(n));
  return true;
}

bool RawSocket::read_until(const std::function<bool(const std::string&)>& done, Clock::time_point deadline) {
  while (!done(received_))
    if (!read_some(deadline)) return done(received_);
  return true;
}

bool RawSocket::read_until_closed(Clock::time_point deadline) {
  while (read_some(deadline)) {
  }
  return closed_;
}

namespace {
std::string lower(std::string s) {
  std::transform(s.begin(), s.end(), s.begin(), [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  return s;
}
}  // namespace

bool HttpResponse::keep_alive() const {
  const auto c = headers.find("connection");
  return c == headers.end() || lower(c->second).find("close") == std::string::npos;
}

std::optional<HttpResponse> take_response(std::string& bytes) {
  const auto end = bytes.find("\r\n\r\n");
  if (end == std::string::npos) return std::nullopt;
  HttpResponse out;
  std::size_t at = bytes.find("\r\n");
  const std::string status_line = bytes.substr(0, at);
  const auto space = status_line.find(' ');
  if (space == std::string::npos) throw std::runtime_error("bad status line: " + status_line);
  out.status = std::stoi(status_line.substr(space + 1, 3));
  while (at < end) {
    const std::size_t next = bytes.find("\r\n", at + 2);
    const std::string line = bytes.substr(at + 2, next - at - 2);
    const auto colon = line.find(':');
    if (colon != std::string::npos) {
      std::string value = line.substr(colon + 1);
      value.erase(0, value.find_first_not_of(' '));
      out.headers[lower(line.substr(0, colon))] = value;
    }
    at = next;
  }
  std::size_t length = 0;
  if (const auto l = out.headers.find("content-length"); l != out.headers.end()) length = std::stoul(l->second);
  if (bytes.size() < end + 4 + length) return std::nullopt;
  out.body = bytes.substr(end + 4, length);
  bytes.erase(0, end + 4 + length);
  return out;
}

std::optional<HttpResponse> read_response(RawSocket& socket, Clock::time_point deadline) {
  std::optional<HttpResponse> out;
  socket.read_until(
      [&](const std::string&) {
        out = take_response(socket.received());
        return out.has_value();
      },
      deadline);
  return out;
}

}  // namespace filigree::test
