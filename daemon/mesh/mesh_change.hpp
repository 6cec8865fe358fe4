// What a split or merge changed, as an ordered log.
//
// Why a log and not net "added/removed" sets: one split may first split its
// ancestors, so an edge or tet can be born and die inside one call, and freed
// ids are reused. Replaying events in order is always right and costs nothing
// to produce; consumers (physics) keep per-id arrays and update them locally.
#pragma once

#include <array>
#include <cstdint>
#include <vector>

namespace tissue::mesh {

using NodeId = std::uint32_t;
using EdgeId = std::uint32_t;
using TetId = std::uint32_t;
inline constexpr std::uint32_t kInvalidId = ~std::uint32_t{0};

struct MeshEvent {
  enum class Kind : std::uint8_t { kNodeAdded, kNodeRemoved, kEdgeAdded, kEdgeRemoved, kTetAdded, kTetRemoved };
  Kind kind{};
  // Tets: bisection depth. Nodes: depth of the diamond that created them.
  std::uint8_t depth = 0;
  std::uint32_t id = kInvalidId;
  // Tets: the four vertices (Maubach order). Edges: endpoints (a, b).
  // Nodes: endpoints of the edge the node splits (its "parents").
  std::array<NodeId, 4> nodes{kInvalidId, kInvalidId, kInvalidId, kInvalidId};
  // Tets only: ids of the six edges (vertex pairs 01 02 03 12 13 23) as they
  // are at this event: a removed tet is logged before any of its edges die,
  // an added tet after its edges exist.
  std::array<EdgeId, 6> edges{kInvalidId, kInvalidId, kInvalidId, kInvalidId, kInvalidId, kInvalidId};
};

// Vertex slots of the six tet edges, in MeshEvent::edges order.
inline constexpr std::array<std::array<int, 2>, 6> kTetEdgeSlots{{{0, 1}, {0, 2}, {0, 3}, {1, 2}, {1, 3}, {2, 3}}};

struct MeshChangeLog {
  std::vector<MeshEvent> events;
  int diamonds_split = 0;
  int diamonds_merged = 0;

  void clear() {
    events.clear();
    diamonds_split = 0;
    diamonds_merged = 0;
  }
  std::size_t count(MeshEvent::Kind kind) const {
    std::size_t n = 0;
    for (const MeshEvent& e : events) n += (e.kind == kind) ? 1 : 0;
    return n;
  }
};

}  // namespace tissue::mesh
