#pragma once
// A WatchPresence stream as the session sees it (session_presence.cpp).

#include <memory>
#include <string>

#include "filigree/v1/filigree.pb.h"

namespace filigree::server {

class PresenceSink {
 public:
  virtual ~PresenceSink() = default;
  // The newest presence; must not block (a slow reader gets the newest).
  virtual void offer(std::shared_ptr<const v1::Presence> presence) = 0;
  // The session closes or leaves this process (as FrameSink::close).
  virtual void close(bool session_closed, const std::string& why) = 0;
};

// A participant's colour, "#rrggbb": fixed for a name (a hash of it over a
// palette readable on the viewer's grey).
std::string participant_colour(const std::string& name);

}  // namespace filigree::server
