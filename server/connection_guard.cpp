#include "server/connection_guard.h"

#include <array>
#include <atomic>
#include <cerrno>
#include <cstdlib>
#include <cstring>
#include <chrono>
#include <stdexcept>
#include <mutex>
#include <optional>
#include <thread>
#include <type_traits>
#include <vector>

#include <fcntl.h>
#include <sys/resource.h>
#include <sys/socket.h>
#include <unistd.h>

#include <utility>  // before Asio: 1.74's awaitable.hpp uses std::exchange without it

#include <boost/asio.hpp>
#include <spdlog/spdlog.h>

#include "server/descriptor_headroom.h"

namespace filigree::server {

namespace asio = boost::asio;
using tcp = asio::ip::tcp;
using unix_socket = asio::local::stream_protocol;

namespace {

// Bytes a relay reads before writing them on: per direction and connection.
constexpr std::size_t kRelayBuffer = 64 * 1024;
// Descriptors that must be free before a connection is relayed, beyond
// those gRPC's pending accepts will take (see room_to_relay).
constexpr std::size_t kRelayDescriptors = 8;

// HOST:PORT, [V6]:PORT → host and port.
std::pair<std::string, std::string> split_address(const std::string& address) {
  const auto colon = address.rfind(':');
  if (colon == std::string::npos) throw std::runtime_error("--listen " + address + " is not HOST:PORT");
  std::string host = address.substr(0, colon);
  if (host.size() >= 2 && host.front() == '[' && host.back() == ']') host = host.substr(1, host.size() - 2);
  return {host.empty() ? std::string("0.0.0.0") : host, address.substr(colon + 1)};
}

}  // namespace

// One relayed connection: the client's socket and the unix socket to gRPC,
// bytes copied both ways; either side's end ends both.
class Relay : public std::enable_shared_from_this<Relay> {
 public:
  // `count`: relays alive; `unaccepted`: relays whose connection gRPC has not
  // accepted yet (it speaks first, its HTTP/2 settings, once it has).
  Relay(tcp::socket client, asio::io_context& io, std::atomic<std::size_t>& count, std::atomic<std::size_t>& unaccepted)
      : client_(std::move(client)), upstream_(io), count_(count), unaccepted_(unaccepted) {
    ++unaccepted_;
  }
  ~Relay() {
    accepted();
    --count_;
  }

  void start(const std::filesystem::path& path) {
    upstream_.async_connect(unix_socket::endpoint(path.string()), [self = shared_from_this()](boost::system::error_code ec) {
      if (ec) {
        spdlog::warn("event=relay_connect_failed error=\"{}\"", ec.message());
        return self->close();
      }
      self->pump(self->client_, self->upstream_, self->to_upstream_);
      self->pump(self->upstream_, self->client_, self->to_client_);
    });
  }

  void close() {
    boost::system::error_code ignored;
    client_.close(ignored);
    upstream_.close(ignored);
  }

 private:
  // Reads from `from` and writes all of it to `to`, until either ends; then
  // half-closes `to` (the other direction may go on: gRPC's end of a call).
  template <class From, class To>
  void pump(From& from, To& to, std::array<char, kRelayBuffer>& buffer) {
    from.async_read_some(asio::buffer(buffer), [self = shared_from_this(), &from, &to, &buffer](boost::system::error_code ec,
                                                                                                 std::size_t n) {
      if constexpr (std::is_same_v<From, unix_socket::socket>) self->accepted();  // gRPC spoke, or went
      if (ec) {
        boost::system::error_code ignored;
        if (ec == asio::error::eof) {
          to.shutdown(asio::socket_base::shutdown_send, ignored);
          if (++self->ended_ == 2) self->close();
        } else {
          self->close();
        }
        return;
      }
      asio::async_write(to, asio::buffer(buffer.data(), n),
                        [self, &from, &to, &buffer](boost::system::error_code ec, std::size_t) {
                          if (ec) return self->close();
                          self->pump(from, to, buffer);
                        });
    });
  }

  void accepted() {
    if (!accepted_) {
      accepted_ = true;
      --unaccepted_;
    }
  }

  tcp::socket client_;
  unix_socket::socket upstream_;
  std::atomic<std::size_t>& count_;
  std::atomic<std::size_t>& unaccepted_;
  bool accepted_ = false;  // the io thread's only
  std::array<char, kRelayBuffer> to_upstream_, to_client_;
  std::atomic<int> ended_{0};
};

struct ConnectionGuard::State : std::enable_shared_from_this<ConnectionGuard::State> {
  explicit State(ConnectionGuardOptions o) : options(std::move(o)), acceptor(io) {}

  void accept() {
    acceptor.async_accept([self = shared_from_this()](boost::system::error_code ec, tcp::socket socket) {
      if (ec == asio::error::operation_aborted || !self->acceptor.is_open()) return;
      if (ec == asio::error::no_descriptors || ec.value() == ENFILE) return self->shed();
      if (!ec) self->admit(std::move(socket));
      self->accept();
    });
  }

  void admit(tcp::socket socket) {
    const bool capped = count.load() >= options.max_connections;
    if (capped || !room_to_relay()) {
      // Over the cap, or too few descriptors left for the relay's socket and
      // gRPC's end of it (gRPC's accept must never see EMFILE: it would stop
      // for good): closed at once, so that it holds nothing.
      spdlog::debug("event=connection_refused reason={} connections={}", capped ? "max_connections" : "descriptors",
                    count.load());
      boost::system::error_code ignored;
      socket.close(ignored);
      return;
    }
    ++count;
    // As gRPC sets on its own sockets: a small frame or pose goes out at once,
    // not after the peer's delayed ACK (40 ms a frame of a small mesh, seen).
    boost::system::error_code ignored;
    socket.set_option(tcp::no_delay(true), ignored);
    // Not make_shared: a weak_ptr left in `relays` would keep the whole
    // object's memory (its two 64 KiB buffers) until pruned.
    std::shared_ptr<Relay> relay(new Relay(std::move(socket), io, count, unaccepted));
    track(relay);
    relay->start(options.upstream);
  }

  // Whether this relay's descriptors (its unix socket, gRPC's accepted end)
  // and a margin fit, beside those still promised to gRPC: relays connected
  // whose connection gRPC has not accepted yet (it has not spoken).
  bool room_to_relay() const {
    return spare >= 0 && descriptors_free(kRelayDescriptors + unaccepted.load());
  }

  // Out of descriptors: give back the spare, take the waiting connection
  // and close it, take the spare again. The next accept waits a moment so
  // that a flood does not spin this thread.
  void shed() {
    const auto now = std::chrono::steady_clock::now();
    if (now - last_shed_log > std::chrono::seconds(10)) {
      last_shed_log = now;
      spdlog::warn("event=descriptors_exhausted connections={} action=closing_new_connections", count.load());
    }
    if (spare >= 0) ::close(spare);
    const int fd = ::accept4(acceptor.native_handle(), nullptr, nullptr, SOCK_CLOEXEC | SOCK_NONBLOCK);
    if (fd >= 0) ::close(fd);
    spare = ::open("/dev/null", O_RDONLY | O_CLOEXEC);
    retry.expires_after(std::chrono::milliseconds(10));
    retry.async_wait([self = shared_from_this()](boost::system::error_code ec) {
      if (!ec) self->accept();
    });
  }

  // Every relay started, to close at stop(); expired ones are dropped once
  // they are as many as the live ones (so the list stays within twice the
  // connections open now, whatever came and went before).
  void track(const std::shared_ptr<Relay>& relay) {
    std::lock_guard lock(relays_mutex);
    if (relays.size() >= 2 * count.load() + 16)
      std::erase_if(relays, [](const std::weak_ptr<Relay>& r) { return r.expired(); });
    relays.push_back(relay);
  }
  void close_all() {
    boost::system::error_code ignored;
    acceptor.close(ignored);
    retry.cancel();
    std::lock_guard lock(relays_mutex);
    for (const auto& weak : relays)
      if (const auto relay = weak.lock()) relay->close();
    relays.clear();
  }

  ConnectionGuardOptions options;
  asio::io_context io;
  tcp::acceptor acceptor;
  asio::steady_timer retry{io};
  std::optional<asio::executor_work_guard<asio::io_context::executor_type>> work;
  std::vector<std::thread> threads;
  std::atomic<std::size_t> count{0}, unaccepted{0};
  std::mutex relays_mutex;
  std::vector<std::weak_ptr<Relay>> relays;
  int spare = -1;
  std::chrono::steady_clock::time_point last_shed_log{};
};

ConnectionGuard::ConnectionGuard(ConnectionGuardOptions options)
    : state_(std::make_shared<State>(std::move(options))) {
  const auto [host, port] = split_address(state_->options.listen);
  boost::system::error_code ec;
  tcp::resolver resolver(state_->io);
  const auto endpoints = resolver.resolve(host, port, tcp::resolver::passive, ec);
  if (ec || endpoints.empty())
    throw std::runtime_error("--listen " + state_->options.listen + ": " + (ec ? ec.message() : "no address"));
  const tcp::endpoint endpoint = *endpoints.begin();
  tcp::acceptor& a = state_->acceptor;
  a.open(endpoint.protocol(), ec);
  if (!ec) a.set_option(tcp::acceptor::reuse_address(true), ec);
  if (!ec) a.bind(endpoint, ec);
  if (!ec) a.listen(asio::socket_base::max_listen_connections, ec);
  if (ec) throw std::runtime_error("cannot listen on " + state_->options.listen + ": " + ec.message());
  state_->spare = ::open("/dev/null", O_RDONLY | O_CLOEXEC);
}

ConnectionGuard::~ConnectionGuard() {
  stop();
  if (state_->spare >= 0) ::close(state_->spare);
}

int ConnectionGuard::port() const { return state_->acceptor.local_endpoint().port(); }

void ConnectionGuard::start() {
  state_->work.emplace(state_->io.get_executor());
  state_->accept();
  state_->threads.emplace_back([s = state_] { s->io.run(); });
}

void ConnectionGuard::stop() {
  if (state_->threads.empty()) return;
  // On the io threads: the acceptor and every relay close, their pending
  // operations end, and run() returns once none is left.
  asio::post(state_->io, [s = state_] { s->close_all(); });
  state_->work.reset();
  for (auto& t : state_->threads) t.join();
  state_->threads.clear();
}

std::size_t ConnectionGuard::connections() const { return state_->count.load(); }

PrivateSocketDir::PrivateSocketDir() {
  std::string pattern = (std::filesystem::temp_directory_path() / "filigree-XXXXXX").string();
  if (!::mkdtemp(pattern.data()))
    throw std::runtime_error(std::string("cannot make a private folder for the gRPC socket: ") + std::strerror(errno));
  dir_ = pattern;
}

PrivateSocketDir::~PrivateSocketDir() {
  std::error_code ignored;
  std::filesystem::remove_all(dir_, ignored);
}

std::size_t connection_budget(std::size_t reserved) {
  rlimit limit{};
  if (::getrlimit(RLIMIT_NOFILE, &limit) == 0 && limit.rlim_cur < limit.rlim_max) {
    limit.rlim_cur = limit.rlim_max;
    ::setrlimit(RLIMIT_NOFILE, &limit);
    ::getrlimit(RLIMIT_NOFILE, &limit);
  }
  const std::size_t open_files = limit.rlim_cur == RLIM_INFINITY ? std::size_t{1} << 20 : limit.rlim_cur;
  // Three descriptors a relayed connection; at least a few connections.
  return std::max<std::size_t>(open_files > reserved ? (open_files - reserved) / 3 : 0, 8);
}

}  // namespace filigree::server
