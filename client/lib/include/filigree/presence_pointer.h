#pragma once
// Where a participant points on the mesh (Client::set_presence), shown to
// the others in their Presence (v1::Participant's pointer).

#include <array>
#include <cstdint>

namespace filigree {

struct PresencePointer {
  std::array<float, 3> position{};  // in the mesh's units
  std::uint32_t vertex = 0;         // the detailed-mesh vertex nearest it (session order)
};

}  // namespace filigree
