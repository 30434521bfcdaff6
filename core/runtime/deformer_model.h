#pragma once
// What the runtime derives once from a hierarchy (DESIGN §3.1): the traversal
// layout of direct recovery and, when a deformer first optimises regions
// (T > 0), the cotangent Laplacian, the differential coordinates and the
// MAPS corners. Immutable once
// built (the lazy parts are built once, thread-safely) and shared read-only by
// every Deformer and every thread of that mesh; a Deformer owns only its
// session's state. Besides, the factorisations of large regions (T = ∞'s
// whole mesh among them) are shared by every deformer of the mesh
// (RegionFactors, thread-safe).

#include <array>
#include <atomic>
#include <cstddef>
#include <exception>
#include <memory>
#include <mutex>
#include <vector>

#include "mesh/tri_mesh.h"

namespace filigree {

struct Hierarchy;
struct CotangentLaplacian;
class NodeGraph;
class DirectRecovery;
class RegionFactors;
template <class T>
class BufferPool;

class DeformerModel {
 public:
  // The model keeps `h` alive. Throws std::invalid_argument if the hierarchy
  // cannot be laid out (a ring larger than the runtime supports).
  static std::shared_ptr<const DeformerModel> create(std::shared_ptr<const Hierarchy> h);
  ~DeformerModel();
  DeformerModel(const DeformerModel&) = delete;
  DeformerModel& operator=(const DeformerModel&) = delete;

  const Hierarchy& hierarchy() const { return *h_; }
  const std::shared_ptr<const Hierarchy>& shared_hierarchy() const { return h_; }
  const DirectRecovery& recovery() const { return *recovery_; }
  // Region optimisation's data: built by the first caller, then shared.
  const CotangentLaplacian& laplacian() const;
  // δ = L x_rest per vertex, the differential coordinates of the rest mesh
  // (DESIGN §2.1.5): derived here rather than stored in the hierarchy.
  const std::vector<Vec3>& differential_coordinates() const;
  // Per vertex: the base-order corners of its MAPS face (thesis §3.1.2).
  const std::vector<std::array<Index, 3>>& maps_corners() const;
  // The hierarchy's node graph, for cuts that change (T > 0): built by the
  // first caller, then shared. Throws HierarchyError if the hierarchy's
  // removals do not delete their fans (hierarchy/node_graph.h): every call,
  // without deriving it again.
  const NodeGraph& node_graph() const;
  // Whether node_graph() has been tried (built, or refused): a call now
  // returns or throws at once, without the derivation's ~0.4 s at 1.25M.
  bool node_graph_derived() const { return graph_tried_.load(std::memory_order_acquire); }
  // Whether region optimisation's data (laplacian() and the rest) is built:
  // the first call builds it, ~1.4 s at 1.25M.
  bool optimisation_data_derived() const { return optimisation_built_.load(std::memory_order_acquire); }
  // Builds what a first finite T needs, node_graph() and the optimisation
  // data, if not built yet: the graph on a second thread meanwhile (they are
  // independent; at 1.25M ~0.8 s beside ~1.4 s). Throws node_graph()'s error.
  void derive_for_cuts() const;
  // The factorisations of large regions, shared by every deformer of the
  // mesh (runtime/regions.h); thread-safe.
  RegionFactors& region_factors() const { return *region_factors_; }
  // Direct recovery's scratch, lent to a deformer for one frame at a time
  // (thread-safe): an idle deformer, a session between frames, holds none.
  BufferPool<float>& recovery_scratch() const { return *recovery_scratch_; }
  // Heap bytes held now: the layout, the lazy parts once built and the shared
  // region factorisations; not the hierarchy, nor the scratch lent out.
  std::size_t memory_bytes() const;

 private:
  explicit DeformerModel(std::shared_ptr<const Hierarchy> h);
  struct Optimisation;
  const Optimisation& optimisation() const;

  std::shared_ptr<const Hierarchy> h_;
  std::unique_ptr<const DirectRecovery> recovery_;
  std::unique_ptr<BufferPool<float>> recovery_scratch_;
  std::unique_ptr<RegionFactors> region_factors_;
  mutable std::once_flag optimisation_once_;
  mutable std::unique_ptr<const Optimisation> optimisation_;
  mutable std::atomic<bool> optimisation_built_{false};  // lets memory_bytes() look without building
  mutable std::once_flag graph_once_;
  mutable std::unique_ptr<const NodeGraph> graph_;
  mutable std::exception_ptr graph_error_;  // set once, under graph_once_
  mutable std::atomic<bool> graph_tried_{false};
};

}  // namespace filigree
