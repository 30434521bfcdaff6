#include "runtime/deformer_model.h"

#include <thread>

#include "geometry/cotangent_laplacian.h"
#include "hierarchy/hierarchy.h"
#include "hierarchy/node_graph.h"
#include "runtime/direct_recovery.h"
#include "runtime/regions.h"
#include "util/buffer_pool.h"

namespace filigree {

struct DeformerModel::Optimisation {
  CotangentLaplacian laplacian;
  std::vector<Vec3> delta;
  std::vector<std::array<Index, 3>> maps_corners;
};

std::shared_ptr<const DeformerModel> DeformerModel::create(std::shared_ptr<const Hierarchy> h) {
  if (!h) throw std::invalid_argument("a deformer model needs a hierarchy");
  return std::shared_ptr<const DeformerModel>(new DeformerModel(std::move(h)));
}

DeformerModel::DeformerModel(std::shared_ptr<const Hierarchy> h)
    : h_(std::move(h)),
      recovery_(std::make_unique<const DirectRecovery>(*h_)),
      // A few frames' worth: as many as deformers of this mesh compute at once.
      recovery_scratch_(std::make_unique<BufferPool<float>>(4)),
      region_factors_(std::make_unique<RegionFactors>()) {}

DeformerModel::~DeformerModel() = default;

const DeformerModel::Optimisation& DeformerModel::optimisation() const {
  std::call_once(optimisation_once_, [this] {
    const Hierarchy& h = *h_;
    auto o = std::make_unique<Optimisation>(Optimisation{cotangent_laplacian(h.rest_positions, h.original_faces), {}, {}});
    o->delta = o->laplacian.apply(h.rest_positions);
    const TriMesh base = h.base_mesh();  // its faces in base order, with base-order corners
    o->maps_corners.resize(h.vertex_count());
    for (Index v = 0; v < h.vertex_count(); ++v) o->maps_corners[v] = base.faces[h.maps_face[v]];
    optimisation_ = std::move(o);
    optimisation_built_.store(true, std::memory_order_release);
  });
  return *optimisation_;
}

void DeformerModel::derive_for_cuts() const {
  {
    std::jthread graph;  // joined at the end of this scope
    if (!node_graph_derived() && std::thread::hardware_concurrency() > 1)
      graph = std::jthread([this] {
        try {
          node_graph();
        } catch (...) {  // a refused graph is remembered by node_graph(), and thrown below
        }
      });
    optimisation();
  }
  node_graph();
}

const CotangentLaplacian& DeformerModel::laplacian() const { return optimisation().laplacian; }

const std::vector<Vec3>& DeformerModel::differential_coordinates() const { return optimisation().delta; }

const std::vector<std::array<Index, 3>>& DeformerModel::maps_corners() const { return optimisation().maps_corners; }

const NodeGraph& DeformerModel::node_graph() const {
  std::call_once(graph_once_, [this] {
    try {
      graph_ = std::make_unique<const NodeGraph>(*h_);
    } catch (const HierarchyError&) {
      graph_error_ = std::current_exception();  // the same answer for every later caller, at no cost
    }
    graph_tried_.store(true, std::memory_order_release);
  });
  if (graph_error_) std::rethrow_exception(graph_error_);
  return *graph_;
}

std::size_t DeformerModel::memory_bytes() const {
  std::size_t bytes = recovery_->memory_bytes();
  if (graph_tried_.load(std::memory_order_acquire) && graph_) bytes += graph_->memory_bytes();
  if (optimisation_built_.load(std::memory_order_acquire)) {
    const Optimisation& o = *optimisation_;
    bytes += o.laplacian.offsets.capacity() * sizeof(Index) + o.laplacian.neighbors.capacity() * sizeof(Index) +
             o.laplacian.weights.capacity() * sizeof(double) + o.delta.capacity() * sizeof(Vec3) +
             o.maps_corners.capacity() * sizeof(o.maps_corners[0]);
  }
  return bytes + region_factors_->memory_bytes();
}

}  // namespace filigree
