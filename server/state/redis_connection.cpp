#include "server/state/redis_connection.h"

#include <algorithm>
#include <cerrno>
#include <system_error>

#include <arpa/inet.h>
#include <fcntl.h>
#include <netdb.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <hiredis/hiredis.h>
#include <openssl/err.h>
#include <openssl/ssl.h>
#include <openssl/x509v3.h>

#include "server/state/redis_tls.h"
#include "server/state/session_store.h"

namespace filigree::server {

// Bytes to and from Redis. read() returns 0 when Redis closed the connection;
// everything else that goes wrong throws StoreUnavailable.
class RedisTransport {
 public:
  virtual ~RedisTransport() = default;
  virtual void write(const char* data, std::size_t size) = 0;
  virtual std::size_t read(char* buffer, std::size_t size) = 0;
};

namespace {

using Clock = std::chrono::steady_clock;

// The socket failed (reset, timed out) after connecting: the TLS transport
// adds what it knows (a handshake that never finished, an alert Redis sent).
struct SocketError : StoreUnavailable {
  using StoreUnavailable::StoreUnavailable;
};

std::string errno_text(int e) { return std::error_code(e, std::system_category()).message(); }

// Waits up to `timeout` for `events` on `fd`: true when ready, false on timeout.
// EINTR (a signal to this thread) waits on for what is left.
bool wait_for(int fd, short events, std::chrono::milliseconds timeout) {
  const auto deadline = Clock::now() + timeout;
  for (;;) {
    const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(deadline - Clock::now());
    pollfd p{fd, events, 0};
    const int n = poll(&p, 1, static_cast<int>(std::max<long long>(0, left.count())));
    if (n > 0) return true;  // ready, or an error/hang-up the next call reports
    if (n == 0) return false;
    if (errno != EINTR) throw StoreUnavailable("poll failed: " + errno_text(errno));
  }
}

// A connected TCP socket, non-blocking so that every wait has a bound.
class Socket {
 public:
  Socket(const std::string& host, int port, const std::string& address, std::chrono::milliseconds timeout)
      : address_(address), timeout_(timeout) {
    addrinfo hints{};
    hints.ai_family = AF_UNSPEC;
    hints.ai_socktype = SOCK_STREAM;
    addrinfo* list = nullptr;
    if (const int rc = getaddrinfo(host.c_str(), std::to_string(port).c_str(), &hints, &list); rc != 0)
      throw StoreUnavailable("cannot connect to Redis at " + address + ": cannot resolve " + host + ": " +
                             gai_strerror(rc));
    const std::unique_ptr<addrinfo, void (*)(addrinfo*)> owned(list, freeaddrinfo);
    std::string failure = "no address";
    // Every address of the name in turn (IPv6 and IPv4), as hiredis did.
    for (const addrinfo* a = list; a && fd_ < 0; a = a->ai_next) {
      const int fd = socket(a->ai_family, a->ai_socktype | SOCK_NONBLOCK | SOCK_CLOEXEC, a->ai_protocol);
      if (fd < 0) {
        failure = errno_text(errno);
        continue;
      }
      if (connect(fd, a->ai_addr, a->ai_addrlen) == 0) {
        fd_ = fd;
      } else if (errno != EINPROGRESS) {
        failure = errno_text(errno);
      } else if (!wait_for(fd, POLLOUT, timeout_)) {
        failure = "no answer within " + std::to_string(timeout_.count()) + " ms";
      } else {
        int error = 0;
        socklen_t size = sizeof error;
        getsockopt(fd, SOL_SOCKET, SO_ERROR, &error, &size);
        if (error == 0)
          fd_ = fd;
        else
          failure = errno_text(error);
      }
      if (fd_ < 0) close(fd);
    }
    if (fd_ < 0) throw StoreUnavailable("cannot connect to Redis at " + address + ": " + failure);
    // Commands are small request/reply exchanges: no Nagle delay. Keepalive
    // (as hiredis' redisEnableKeepAlive) finds a peer that vanished silently.
    const int one = 1, idle = 15, interval = 5, count = 3;
    setsockopt(fd_, IPPROTO_TCP, TCP_NODELAY, &one, sizeof one);
    setsockopt(fd_, SOL_SOCKET, SO_KEEPALIVE, &one, sizeof one);
    setsockopt(fd_, IPPROTO_TCP, TCP_KEEPIDLE, &idle, sizeof idle);
    setsockopt(fd_, IPPROTO_TCP, TCP_KEEPINTVL, &interval, sizeof interval);
    setsockopt(fd_, IPPROTO_TCP, TCP_KEEPCNT, &count, sizeof count);
  }
  ~Socket() {
    if (fd_ >= 0) close(fd_);
  }
  Socket(const Socket&) = delete;
  Socket& operator=(const Socket&) = delete;

  // MSG_NOSIGNAL: a peer that closed gives EPIPE here, not a SIGPIPE that kills the server.
  void send_all(const char* data, std::size_t size) {
    while (size > 0) {
      const ssize_t n = send(fd_, data, size, MSG_NOSIGNAL);
      if (n > 0) {
        data += n;
        size -= static_cast<std::size_t>(n);
      } else if (errno == EAGAIN || errno == EWOULDBLOCK) {
        wait(POLLOUT);
      } else if (errno != EINTR) {
        throw SocketError("the connection to Redis at " + address_ + " failed: " + errno_text(errno));
      }
    }
  }
  // Some bytes, or 0 when Redis closed the connection.
  std::size_t receive(char* buffer, std::size_t size) {
    for (;;) {
      const ssize_t n = recv(fd_, buffer, size, 0);
      if (n >= 0) return static_cast<std::size_t>(n);
      if (errno == EAGAIN || errno == EWOULDBLOCK) {
        wait(POLLIN);
      } else if (errno == ECONNRESET) {
        return 0;  // as a close: the caller says so with its context
      } else if (errno != EINTR) {
        throw SocketError("the connection to Redis at " + address_ + " failed: " + errno_text(errno));
      }
    }
  }
  // What has already arrived, without waiting: 0 if nothing (or the socket failed).
  std::size_t receive_pending(char* buffer, std::size_t size) {
    const ssize_t n = recv(fd_, buffer, size, MSG_DONTWAIT);
    return n > 0 ? static_cast<std::size_t>(n) : 0;
  }

 private:
  // The timeout bounds each wait for progress, not a whole command: a large
  // hierarchy that keeps flowing may take longer than one timeout in all.
  void wait(short events) {
    if (!wait_for(fd_, events, timeout_))
      throw SocketError("Redis at " + address_ + " did not answer within " + std::to_string(timeout_.count()) + " ms");
  }

  int fd_ = -1;
  std::string address_;
  std::chrono::milliseconds timeout_;
};

class PlainTransport final : public RedisTransport {
 public:
  explicit PlainTransport(std::unique_ptr<Socket> socket) : socket_(std::move(socket)) {}
  void write(const char* data, std::size_t size) override { socket_->send_all(data, size); }
  std::size_t read(char* buffer, std::size_t size) override { return socket_->receive(buffer, size); }

 private:
  std::unique_ptr<Socket> socket_;
};

// TLS through memory BIOs: OpenSSL only encrypts and decrypts, and the socket
// above does all the I/O, so TLS gets the same timeouts and MSG_NOSIGNAL as
// plaintext (an OpenSSL socket BIO would write() and could raise SIGPIPE).
class TlsTransport final : public RedisTransport {
 public:
  TlsTransport(std::unique_ptr<Socket> socket, const RedisTls& tls, const std::string& host, const std::string& address)
      : socket_(std::move(socket)), tls_(tls), address_(address), name_(tls.server_name(host)) {
    ERR_clear_error();
    ssl_ = SSL_new(tls.context());
    BIO* in = BIO_new(BIO_s_mem());
    BIO* out = BIO_new(BIO_s_mem());
    if (!ssl_ || !in || !out) {
      BIO_free(in);
      BIO_free(out);
      throw StoreUnavailable("TLS to Redis at " + address_ + ": out of memory");
    }
    SSL_set_bio(ssl_, in, out);  // the SSL owns both from here
    in_ = in;
    out_ = out;
    // The name to verify: an IP address is matched against the certificate's
    // IP entries, and sent without SNI (RFC 6066 allows only host names there).
    X509_VERIFY_PARAM* param = SSL_get0_param(ssl_);
    unsigned char ip[sizeof(in6_addr)];
    if (inet_pton(AF_INET, name_.c_str(), ip) == 1 || inet_pton(AF_INET6, name_.c_str(), ip) == 1) {
      X509_VERIFY_PARAM_set1_ip_asc(param, name_.c_str());
    } else {
      SSL_set_tlsext_host_name(ssl_, name_.c_str());
      X509_VERIFY_PARAM_set_hostflags(param, X509_CHECK_FLAG_NO_PARTIAL_WILDCARDS);
      X509_VERIFY_PARAM_set1_host(param, name_.c_str(), 0);
    }
    SSL_set_connect_state(ssl_);
    int done = 0;
    try {
      done = drive([this] { return SSL_do_handshake(ssl_); }, true);
    } catch (const SocketError& e) {
      // A plaintext Redis reads the ClientHello as the start of a command and waits for its end.
      throw StoreUnavailable(std::string(e.what()) + " during the TLS handshake (is its port a TLS port?)");
    }
    if (done == 0)
      throw StoreUnavailable("Redis at " + address_ + " closed the connection during the TLS handshake" +
                             " (is its port a TLS port?)");
  }
  ~TlsTransport() override { SSL_free(ssl_); }

  void write(const char* data, std::size_t size) override {
    // In 64 KiB pieces, each sent before the next is encrypted: a 100 MiB
    // hierarchy is never held twice in memory.
    constexpr std::size_t kPiece = 64 * 1024;
    while (size > 0) {
      const int piece = static_cast<int>(std::min(size, kPiece));
      if (drive([&] { return SSL_write(ssl_, data, piece); }, false) == 0)
        throw StoreUnavailable(closed() + " while a command was sent");
      data += piece;
      size -= static_cast<std::size_t>(piece);
    }
  }
  std::size_t read(char* buffer, std::size_t size) override {
    const int n =
        drive([&] { return SSL_read(ssl_, buffer, static_cast<int>(std::min<std::size_t>(size, 1 << 30))); }, false);
    return static_cast<std::size_t>(n);
  }

 private:
  // Runs `op` until it succeeds, moving bytes between the socket and OpenSSL
  // as it asks. Its result, or 0 when Redis closed the connection.
  template <typename Op>
  int drive(Op op, bool handshake) {
    for (;;) {
      ERR_clear_error();  // SSL_get_error reads this thread's queue: nothing stale in it
      const int r = op();
      const int error = r > 0 ? SSL_ERROR_NONE : SSL_get_error(ssl_, r);
      if (error == SSL_ERROR_NONE) {
        flush();
        return r;
      }
      if (error == SSL_ERROR_WANT_READ || error == SSL_ERROR_WANT_WRITE) {
        flush();
        if (error == SSL_ERROR_WANT_READ && !fill()) return 0;
        continue;
      }
      if (error == SSL_ERROR_ZERO_RETURN) return 0;  // Redis' close_notify
      fail(handshake);
    }
  }

  // Sends what OpenSSL has encrypted. If that fails, Redis may have said why
  // before it closed: with TLS 1.3 a refused client certificate is an alert
  // that arrives after the client's handshake is done, as it sends its first
  // command. Read it and report it (fail()), rather than the bare reset.
  void flush(bool explain = true) {
    char* data = nullptr;
    const long size = BIO_get_mem_data(out_, &data);
    if (size <= 0) return;
    try {
      socket_->send_all(data, static_cast<std::size_t>(size));
    } catch (const SocketError&) {
      if (explain) read_alert();
      throw;
    }
    (void)BIO_reset(out_);
  }
  // After a failed send: whatever Redis sent before it closed, through OpenSSL;
  // an alert among it throws (fail). Returns if there is none.
  void read_alert() {
    char buffer[16 * 1024 + 512];
    for (std::size_t n; (n = socket_->receive_pending(buffer, sizeof buffer)) > 0;)
      BIO_write(in_, buffer, static_cast<int>(n));
    for (;;) {
      ERR_clear_error();
      const int r = SSL_read(ssl_, buffer, sizeof buffer);  // application data is dropped: the command failed
      if (r > 0) continue;
      if (SSL_get_error(ssl_, r) == SSL_ERROR_SSL) fail(false);
      return;
    }
  }
  // Gives OpenSSL what Redis sent; false when Redis closed the connection.
  bool fill() {
    char buffer[16 * 1024 + 512];  // one TLS record and its overhead
    const std::size_t n = socket_->receive(buffer, sizeof buffer);
    if (n == 0) return false;
    BIO_write(in_, buffer, static_cast<int>(n));
    return true;
  }

  [[noreturn]] void fail(bool handshake) {
    const unsigned long e = ERR_peek_error();
    // OpenSSL queued an alert for Redis (bad certificate, ...): tell it, best effort.
    try {
      flush(false);
    } catch (const StoreUnavailable&) {
    }
    const long verify = SSL_get_verify_result(ssl_);
    if (handshake && verify != X509_V_OK)
      throw StoreUnavailable("cannot verify the TLS certificate of Redis at " + address_ + ": " +
                             X509_verify_cert_error_string(verify) + " (trusting " + tls_.trust() +
                             ", expecting the name '" + name_ + "')");
    const std::string reason = openssl_reason(e);
    ERR_clear_error();
    const int code = ERR_GET_REASON(e);
    // Reasons from SSL_AD_REASON_OFFSET on are alerts Redis sent: it refused us.
    if (ERR_GET_LIB(e) == ERR_LIB_SSL && code >= SSL_AD_REASON_OFFSET && code < SSL_AD_REASON_OFFSET + 256) {
      const int alert = code - SSL_AD_REASON_OFFSET;
      const bool about_certificate = alert == SSL_AD_CERTIFICATE_REQUIRED || alert == SSL_AD_HANDSHAKE_FAILURE ||
                                     alert == SSL_AD_BAD_CERTIFICATE || alert == SSL_AD_UNKNOWN_CA ||
                                     alert == SSL_AD_CERTIFICATE_UNKNOWN;
      std::string hint;
      if (about_certificate)
        hint = tls_.client_cert().empty()
                   ? " (Redis wants a client certificate, tls-auth-clients: give --redis-tls-cert and --redis-tls-key)"
                   : " (Redis does not accept the client certificate " + tls_.client_cert() + ")";
      throw StoreUnavailable("Redis at " + address_ + " refused the TLS connection: " + reason + hint);
    }
    if (handshake && ERR_GET_LIB(e) == ERR_LIB_SSL &&
        (code == SSL_R_WRONG_VERSION_NUMBER || code == SSL_R_PACKET_LENGTH_TOO_LONG))
      throw StoreUnavailable("TLS handshake with Redis at " + address_ + " failed: " + reason +
                             " (is its port a TLS port? a plaintext Redis does not answer TLS)");
    throw StoreUnavailable(std::string(handshake ? "TLS handshake with" : "TLS error from") + " Redis at " + address_ +
                           " failed: " + reason);
  }

  std::string closed() const { return "Redis at " + address_ + " closed the TLS connection"; }

  std::unique_ptr<Socket> socket_;
  const RedisTls& tls_;
  std::string address_, name_;
  SSL* ssl_ = nullptr;
  BIO* in_ = nullptr;   // owned by ssl_
  BIO* out_ = nullptr;  // owned by ssl_
};

RedisReply convert(const redisReply& r) {
  RedisReply out;
  switch (r.type) {
    case REDIS_REPLY_STRING:
      out.type = RedisReply::Type::kString;
      out.str.assign(r.str, r.len);
      break;
    case REDIS_REPLY_STATUS:
      out.type = RedisReply::Type::kStatus;
      out.str.assign(r.str, r.len);
      break;
    case REDIS_REPLY_INTEGER:
      out.type = RedisReply::Type::kInteger;
      out.integer = r.integer;
      break;
    case REDIS_REPLY_ARRAY:
      out.type = RedisReply::Type::kArray;
      for (std::size_t i = 0; i < r.elements; ++i) out.elements.push_back(convert(*r.element[i]));
      break;
    default:
      break;
  }
  return out;
}

}  // namespace

RedisConnection::RedisConnection(const std::string& host, int port, const std::string& address,
                                 std::chrono::milliseconds timeout, const RedisTls* tls)
    : address_(address), tls_(tls != nullptr), buffer_(64 * 1024) {
  auto socket = std::make_unique<Socket>(host, port, address, timeout);
  if (tls)
    transport_ = std::make_unique<TlsTransport>(std::move(socket), *tls, host, address);
  else
    transport_ = std::make_unique<PlainTransport>(std::move(socket));
  reader_ = redisReaderCreate();
  if (!reader_) throw StoreUnavailable("Redis at " + address_ + ": out of memory for a reply reader");
}

RedisConnection::~RedisConnection() {
  if (reader_) redisReaderFree(reader_);
}

std::string RedisConnection::closed_message() const {
  std::string message = "Redis at " + address_ + " closed the connection";
  // A TLS-only Redis closes a plaintext connection at its first bytes.
  if (!tls_ && !answered_) message += " before any reply (if it serves only TLS, give --redis-tls)";
  return message;
}

RedisConnection::Answer RedisConnection::command(const std::vector<std::string_view>& args) {
  std::vector<const char*> argv;
  std::vector<std::size_t> lengths;
  for (const auto& a : args) argv.push_back(a.data()), lengths.push_back(a.size());
  char* formatted = nullptr;
  const int size = redisFormatCommandArgv(&formatted, static_cast<int>(args.size()), argv.data(), lengths.data());
  if (size < 0) throw StoreUnavailable("Redis at " + address_ + ": out of memory for a command");
  {
    const std::unique_ptr<char, void (*)(char*)> owned(formatted, redisFreeCommand);
    transport_->write(formatted, static_cast<std::size_t>(size));
  }
  for (;;) {
    void* raw = nullptr;
    if (redisReaderGetReply(reader_, &raw) != REDIS_OK) {
      std::string message = "Redis at " + address_ + " sent something that is not a Redis reply: " + reader_->errstr;
      if (!tls_ && !answered_) message += " (if it serves only TLS, give --redis-tls)";
      throw StoreUnavailable(message);
    }
    if (raw) {
      const std::unique_ptr<redisReply, void (*)(void*)> reply(static_cast<redisReply*>(raw), freeReplyObject);
      answered_ = true;
      Answer answer;
      if (reply->type == REDIS_REPLY_ERROR)
        answer.error = std::string(reply->str, reply->len);
      else
        answer.reply = convert(*reply);
      return answer;
    }
    const std::size_t n = transport_->read(buffer_.data(), buffer_.size());
    if (n == 0) throw StoreUnavailable(closed_message());
    if (redisReaderFeed(reader_, buffer_.data(), n) != REDIS_OK)
      throw StoreUnavailable("Redis at " + address_ + ": out of memory for a reply");
  }
}

}  // namespace filigree::server
