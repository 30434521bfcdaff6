// Presence: who is in a session and what they touch; pointers.

#include <cstdlib>

#include "c_api/collaboration.h"

namespace filigree::c_api {
namespace {

// 0xRRGGBB of "#rrggbb" (0 for anything else).
std::uint32_t colour_of(const std::string& text) {
  if (text.size() != 7 || text[0] != '#') return 0;
  char* end = nullptr;
  const unsigned long value = std::strtoul(text.c_str() + 1, &end, 16);
  return end == text.c_str() + 7 ? static_cast<std::uint32_t>(value) : 0;
}

// Runs `body(handle, participant)` for participant `index` of the presence polled.
template <class Body>
int with_participant(const filigree_presence* presence, const char* function, std::size_t index, Body&& body) {
  return with_handle(presence, function, [&](const filigree_presence& p) -> int {
    const std::shared_ptr<const v1::Presence> polled = p.feed->polled();
    if (index >= static_cast<std::size_t>(polled->participants_size()))
      return fail(&p.error, FILIGREE_OUT_OF_RANGE,
                  std::string(function) + ": participant " + std::to_string(index) + " of " +
                      std::to_string(polled->participants_size()));
    return body(p, polled->participants(static_cast<int>(index)));
  });
}

}  // namespace
}  // namespace filigree::c_api

using namespace filigree::c_api;

extern "C" {

int filigree_presence_open(filigree_session* session, const char* token, const char* client_name,
                           filigree_presence** out) {
  constexpr const char* kFunction = "filigree_presence_open";
  return with_handle(session, kFunction, [&](filigree_session& s) -> int {
    if (!out) return null_argument(&s.error, kFunction, "out");
    *out = nullptr;
    auto handle = std::make_unique<filigree_presence>();
    handle->connection = s.connection;
    handle->feed = std::make_unique<PresenceFeed>(s.connection->client.watch_presence(
        s.mesh.session_id, token ? token : s.token, client_name ? client_name : "filigree-c"));
    return hand_out(std::move(handle), out);
  });
}

int filigree_presence_poll(filigree_presence* presence, uint64_t* version, int* updated) {
  constexpr const char* kFunction = "filigree_presence_poll";
  return with_handle(presence, kFunction,
                     [&](filigree_presence& p) { return p.feed->poll(p.error, kFunction, version, updated); });
}

int filigree_presence_wait(filigree_presence* presence, int64_t timeout_ms) {
  constexpr const char* kFunction = "filigree_presence_wait";
  return with_handle(presence, kFunction,
                     [&](filigree_presence& p) { return p.feed->wait(p.error, kFunction, timeout_of(timeout_ms)); });
}

int filigree_presence_participant_count(const filigree_presence* presence, size_t* count) {
  constexpr const char* kFunction = "filigree_presence_participant_count";
  return with_handle(presence, kFunction, [&](const filigree_presence& p) -> int {
    if (!count) return null_argument(&p.error, kFunction, "count");
    *count = static_cast<std::size_t>(p.feed->polled()->participants_size());
    return FILIGREE_OK;
  });
}

int filigree_presence_participant_get(const filigree_presence* presence, size_t index,
                                      filigree_participant* participant) {
  constexpr const char* kFunction = "filigree_presence_participant_get";
  return with_participant(presence, kFunction, index,
                          [&](const filigree_presence& p, const filigree::v1::Participant& q) -> int {
                            if (!participant) return null_argument(&p.error, kFunction, "participant");
                            *participant = filigree_participant{};
                            participant->role = q.role() == filigree::v1::Participant::ROLE_EDITOR ? 1 : 0;
                            participant->colour = colour_of(q.colour());
                            participant->has_pointer = q.has_pointer() ? 1 : 0;
                            participant->pointer[0] = q.pointer_x();
                            participant->pointer[1] = q.pointer_y();
                            participant->pointer[2] = q.pointer_z();
                            participant->pointer_vertex = q.pointer_vertex();
                            participant->idle_seconds = q.idle_seconds();
                            participant->touching_count = static_cast<uint64_t>(q.touching_size());
                            participant->handle_count = static_cast<uint64_t>(q.handle_vertices_size());
                            return FILIGREE_OK;
                          });
}

int filigree_presence_participant_name(const filigree_presence* presence, size_t index, char* buffer, size_t capacity,
                                       size_t* required) {
  constexpr const char* kFunction = "filigree_presence_participant_name";
  return with_participant(presence, kFunction, index, [&](const filigree_presence& p, const filigree::v1::Participant& q) {
    return copy_string(&p.error, kFunction, q.client_name(), buffer, capacity, required);
  });
}

int filigree_presence_participant_touching(const filigree_presence* presence, size_t index, uint32_t* buffer,
                                           size_t capacity, size_t* required) {
  constexpr const char* kFunction = "filigree_presence_participant_touching";
  return with_participant(presence, kFunction, index, [&](const filigree_presence& p, const filigree::v1::Participant& q) {
    return copy_out(&p.error, kFunction, q.touching().data(), static_cast<std::size_t>(q.touching_size()),
                    sizeof(std::uint32_t), buffer, capacity, required);
  });
}

int filigree_presence_participant_handles(const filigree_presence* presence, size_t index, uint32_t* buffer,
                                          size_t capacity, size_t* required) {
  constexpr const char* kFunction = "filigree_presence_participant_handles";
  return with_participant(presence, kFunction, index, [&](const filigree_presence& p, const filigree::v1::Participant& q) {
    return copy_out(&p.error, kFunction, q.handle_vertices().data(), static_cast<std::size_t>(q.handle_vertices_size()),
                    sizeof(std::uint32_t), buffer, capacity, required);
  });
}

int filigree_presence_close(filigree_presence* presence) {
  constexpr const char* kFunction = "filigree_presence_close";
  return with_handle(presence, kFunction, [&](filigree_presence& p) -> int {
    p.feed->stop();
    p.feed->join();
    const PresenceFeed::End end = p.feed->end();
    if (end.status == FILIGREE_OK) return FILIGREE_OK;
    return fail(&p.error, end.status, std::string(kFunction) + ": the stream ended: " + end.message);
  });
}

const char* filigree_presence_last_error(const filigree_presence* presence) {
  return is_handle(presence, filigree_presence::kKind) ? presence->error.get() : invalid_handle_message();
}

int filigree_presence_free(filigree_presence* presence) {
  if (!presence) return FILIGREE_OK;
  if (!unregister_handle(presence, filigree_presence::kKind))
    return fail(nullptr, FILIGREE_ERROR_INVALID_HANDLE,
                "filigree_presence_free: not a live filigree_presence (freed, or another kind of handle)");
  delete presence;  // the feed stops and joins its thread
  return FILIGREE_OK;
}

int filigree_set_presence(filigree_session* session, const char* token, const char* client_name, const float* pointer,
                          uint32_t pointer_vertex) {
  return with_handle(session, "filigree_set_presence", [&](filigree_session& s) -> int {
    std::optional<filigree::PresencePointer> at;
    if (pointer) at = filigree::PresencePointer{{pointer[0], pointer[1], pointer[2]}, pointer_vertex};
    s.connection->client.set_presence(s.mesh.session_id, token ? token : s.token,
                                      client_name ? client_name : "filigree-c", at);
    return FILIGREE_OK;
  });
}

}  // extern "C"
