#include "server/session.h"
// Session's presence (proto Presence): who is here, their role, what they
// touch and point at, sent to every WatchPresence stream when it changes.

#include <algorithm>
#include <array>
#include <functional>

namespace filigree::server {
namespace {

using Clock = std::chrono::steady_clock;

// A change's vertices count as being touched this long after it.
constexpr double kTouchingSeconds = 10.0;
// Presence for pose changes goes out at most this often (a drag merges 60 a second).
constexpr auto kPresencePacing = std::chrono::milliseconds(100);

}  // namespace

std::string participant_colour(const std::string& name) {
  static constexpr std::array<const char*, 8> kPalette = {"#e6194b", "#3cb44b", "#4363d8", "#f58231",
                                                          "#911eb4", "#bfef45", "#f032e6", "#9a6324"};
  // FNV-1a: the same colour on every server and in every client that hashes alike.
  std::uint32_t h = 2166136261u;
  for (unsigned char c : name) h = (h ^ c) * 16777619u;
  return kPalette[h % kPalette.size()];
}

v1::Presence Session::presence_locked() const {
  v1::Presence out;
  out.set_version(record_.version);
  const double now = unix_seconds();
  const auto steady = Clock::now();
  std::map<std::string, v1::Participant> by_name;
  const auto participant = [&](const std::string& name) -> v1::Participant& {
    v1::Participant& p = by_name[name];
    if (p.client_name().empty() && !name.empty()) {
      p.set_client_name(name);
      p.set_colour(participant_colour(name));
      p.set_idle_seconds(1e9);
    }
    return p;
  };
  for (const auto& [name, state] : presence_) {
    if (state.streams == 0 && !state.pointer) continue;
    v1::Participant& p = participant(name);
    p.set_role(state.role == Role::kEditor ? v1::Participant::ROLE_EDITOR : v1::Participant::ROLE_VIEWER);
    p.set_idle_seconds(std::chrono::duration<double>(steady - state.active).count());
    if (state.pointer) {
      p.set_has_pointer(true);
      p.set_pointer_x(state.pointer->x);
      p.set_pointer_y(state.pointer->y);
      p.set_pointer_z(state.pointer->z);
      p.set_pointer_vertex(state.pointer->vertex);
    }
  }
  for (const auto& [v, entries] : handles_)
    for (const HandleEntry& e : entries) {
      v1::Participant& p = participant(e.client);
      p.set_role(v1::Participant::ROLE_EDITOR);
      p.add_handle_vertices(v);
    }
  for (const auto& [name, latest] : history_.latest_by_author()) {
    const double age = now - latest.second;
    if (age > kTouchingSeconds) continue;
    v1::Participant& p = participant(name);
    p.set_role(v1::Participant::ROLE_EDITOR);
    p.mutable_touching()->Add(latest.first.begin(), latest.first.end());
    p.set_idle_seconds(std::min(p.idle_seconds(), std::max(age, 0.0)));
  }
  for (auto& [name, p] : by_name)
    if (!name.empty()) *out.add_participants() = std::move(p);
  return out;
}

void Session::publish_presence_locked(bool paced) {
  const auto now = Clock::now();
  if (paced && now - presence_published_ < kPresencePacing) {
    presence_dirty_ = true;  // the next tick or event sends it
    return;
  }
  presence_dirty_ = false;
  presence_published_ = now;
  std::erase_if(presence_sinks_, [](const std::weak_ptr<PresenceSink>& w) { return w.expired(); });
  if (presence_sinks_.empty()) return;
  auto snapshot = std::make_shared<const v1::Presence>(presence_locked());
  for (const auto& w : presence_sinks_)
    if (const auto sink = w.lock()) sink->offer(snapshot);
}

void Session::join_presence(const std::shared_ptr<PresenceSink>& sink, const std::string& name, Role role) {
  std::lock_guard lock(mutex_);
  if (closed_) {
    sink->close(!evicted_, "session " + record_.id + " left this server's memory as the stream opened: reconnect");
    return;
  }
  PresenceState& state = presence_[name];
  ++state.streams;
  state.role = std::max(state.role, role);
  state.active = Clock::now();
  presence_sinks_.push_back(sink);
  publish_presence_locked(false);
}

void Session::leave_presence(const PresenceSink* sink, const std::string& name) {
  std::lock_guard lock(mutex_);
  std::erase_if(presence_sinks_, [&](const std::weak_ptr<PresenceSink>& w) {
    const auto s = w.lock();
    return !s || s.get() == sink;
  });
  if (const auto it = presence_.find(name); it != presence_.end() && it->second.streams > 0 && --it->second.streams == 0 &&
                                             !it->second.pointer)
    presence_.erase(it);
  publish_presence_locked(false);
}

void Session::point(const std::string& name, Role role, std::optional<Pointer> pointer) {
  std::lock_guard lock(mutex_);
  PresenceState& state = presence_[name];
  state.role = std::max(state.role, role);
  state.pointer = pointer;
  state.active = Clock::now();
  if (!pointer && state.streams == 0) presence_.erase(name);
  publish_presence_locked(true);
}

void Session::flush_presence() {
  std::lock_guard lock(mutex_);
  if (presence_dirty_) publish_presence_locked(false);
}

}  // namespace filigree::server
