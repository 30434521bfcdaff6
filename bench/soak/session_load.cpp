#include "bench/soak/session_load.h"

#include <algorithm>
#include <cmath>
#include <cstring>

namespace filigree::soak {

namespace {

std::string driver_name(int index) { return "soak-driver-" + std::to_string(index); }

// The end's unary calls go through the raw stub with the end's deadline (at
// least 2 s for each call once it has passed), not the library's fixed call
// timeout: a server that died or hangs must fail the soak by its end, not
// stall it (a CloseSession to a killed server was seen to wait forever).
void prepare(grpc::ClientContext& context, const SessionHandle& s, const std::string& token,
             std::chrono::steady_clock::time_point deadline) {
  const auto left = std::max<std::chrono::steady_clock::duration>(deadline - std::chrono::steady_clock::now(),
                                                                   std::chrono::seconds(2));
  context.set_deadline(std::chrono::system_clock::now() + left);
  set_session_metadata(context, s.session_id, token);
}

std::string describe(const grpc::Status& status) {
  return std::string(status_code_name(status.error_code())) + ": " + status.error_message();
}

// How far behind the driver a slow watcher may read: the frames in flight
// (two) and those computed during three of its reads (the one in flight was
// sent during the read before), doubled for a busy machine, where a reader
// is descheduled for longer than its delay (24 and 25 behind were seen with
// a fuzzer and browser tests on both cores). Without acknowledgements it
// reads hundreds to thousands behind.
std::uint64_t slow_lag_limit(const Options& o) {
  const double per_read = o.rate_hz * std::chrono::duration<double>(o.slow_reader_delay).count();
  return 2 + 6 * static_cast<std::uint64_t>(std::ceil(per_read)) + 8;
}

}  // namespace

SessionLoad::SessionLoad(Client& client, const std::string& address, const SessionHandle& session, int index,
                         const Options& options, Failures& failures)
    : client_(client), session_(session), options_(options), failures_(failures),
      // A client of its own with the library's default channel: no small
      // window needed, since its watcher acknowledges what it read.
      slow_client_(address),
      // Phases spread over the sessions, so that they do not all bend in step.
      driver_(client, session, driver_name(index), options.rate_hz, 0.7 * index, failures) {
  for (WatcherKind kind : {WatcherKind::kNormal, WatcherKind::kSlow, WatcherKind::kReconnecting})
    watchers_[static_cast<int>(kind)] =
        std::make_unique<SoakWatcher>(kind == WatcherKind::kSlow ? slow_client_ : client, session, kind, driver_name(index),
                                      options.slow_reader_delay, options.reconnect_every, failures,
                                      [this] { return driver_.stats().last_version; }, slow_lag_limit(options));
}

SessionLoad::~SessionLoad() {
  driver_.stop_posing();
  for (auto& w : watchers_) w->stop();
}

void SessionLoad::start() {
  for (auto& w : watchers_) w->start();
  driver_.start();
}

void SessionLoad::stop_posing() {
  driver_.stop_posing();
  for (auto& w : watchers_) w->end_delay();
}

void SessionLoad::finish_and_check(std::chrono::steady_clock::time_point deadline) {
  const std::optional<std::uint64_t> version = driver_.finish(deadline);
  if (version && driver_.last_pose_id() != 0) {
    check_state(*version, deadline);
    for (auto& w : watchers_) {
      if (!w->wait_for_version(*version, deadline)) {
        failures_.add(w->name() + ": never received frame " + std::to_string(*version) + " (the last pose's; newest " +
                      std::to_string(w->stats().newest_version) + ")");
        continue;
      }
      const WatcherStats s = w->stats();
      // No frame may follow the last pose's: nothing else changes the session
      // (the malformed requests were all refused before they could).
      if (s.newest_version != *version)
        failures_.add(w->name() + ": received frame " + std::to_string(s.newest_version) + " after the last pose's frame " +
                      std::to_string(*version));
      else if (s.newest_driver_pose != driver_.last_pose_id())
        failures_.add(w->name() + ": the final frame " + std::to_string(*version) + " names pose " +
                      std::to_string(s.newest_driver_pose) + ", not the last pose " + std::to_string(driver_.last_pose_id()));
    }
  }
  for (auto& w : watchers_) w->stop();
  grpc::ClientContext context;
  prepare(context, session_, session_.editor_token, deadline);
  v1::CloseSessionRequest request;
  request.set_session_id(session_.session_id);
  v1::CloseSessionResponse response;
  if (const grpc::Status status = client_.stub().CloseSession(&context, request, &response); !status.ok())
    failures_.add(driver_.name() + ": CloseSession failed: " + describe(status));
}

void SessionLoad::check_state(std::uint64_t version, std::chrono::steady_clock::time_point deadline) {
  const std::string& who = driver_.name();
  grpc::ClientContext context;
  prepare(context, session_, session_.viewer_token, deadline);
  v1::GetStateRequest request;
  request.set_session_id(session_.session_id);
  request.set_frame_format(v1::FRAME_FORMAT_CHUNKED);
  v1::SessionState state;
  if (const grpc::Status status = client_.stub().GetState(&context, request, &state); !status.ok()) {
    failures_.add(who + ": GetState failed: " + describe(status));
    return;
  }
  if (state.version() != version || state.frame().version() != version)
    failures_.add(who + ": GetState says version " + std::to_string(state.version()) + " (frame " +
                  std::to_string(state.frame().version()) + "), the last pose's frame is " + std::to_string(version));
  const std::vector<float>& pose = driver_.last_pose();
  // Bit for bit: the server merges the floats it was sent, and every later
  // pose (there is none) or refused one (there are many) must leave them.
  if (static_cast<std::size_t>(state.pose_size()) != pose.size() ||
      std::memcmp(state.pose().data(), pose.data(), pose.size() * sizeof(float)) != 0)
    failures_.add(who + ": GetState's merged pose is not the last pose " + std::to_string(driver_.last_pose_id()));
  if (const std::uint64_t named = pose_in_changes(state.frame(), who); named != driver_.last_pose_id())
    failures_.add(who + ": GetState's frame names pose " + std::to_string(named) + ", not the last pose " +
                  std::to_string(driver_.last_pose_id()));
}

SessionSummary SessionLoad::summary() const {
  SessionSummary s;
  s.driver = driver_.stats();
  for (int k = 0; k < 3; ++k) s.watchers[k] = watchers_[k]->stats();
  if (s.driver.frame_seconds > 0.0)
    s.fps = static_cast<double>(s.driver.last_version - s.driver.first_version) / s.driver.frame_seconds;
  return s;
}

}  // namespace filigree::soak
