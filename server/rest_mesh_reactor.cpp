#include "server/rest_mesh_reactor.h"

#include <algorithm>
#include <cstddef>
#include <memory>
#include <span>
#include <utility>

#include "hierarchy/hierarchy.h"
#include "server/filigree_service.h"
#include "server/session.h"

namespace filigree::server {
namespace {

// Values per part (RestMeshPart's promise): 512 KiB of floats, under the
// smallest --max-message-mib.
constexpr std::size_t kPartValues = std::size_t{1} << 17;

// Writes the parts one at a time: each is made when the previous one is
// written, so a call holds one part, whatever the mesh's size.
class RestMeshReactor final : public grpc::ServerWriteReactor<v1::RestMeshPart> {
 public:
  RestMeshReactor(FiligreeService& service, grpc::CallbackServerContext* context, const v1::GetRestMeshRequest& request) {
    service.with_session(*context, request.session_id(), Role::kViewer, [this](grpc::Status status, std::shared_ptr<Session> s) {
      if (!status.ok()) return Finish(status);
      session_ = std::move(s);
      write_next();
    });
  }

  void OnWriteDone(bool ok) override {
    if (!ok) return Finish(grpc::Status::CANCELLED);  // the client went away
    write_next();
  }
  void OnDone() override { delete this; }

 private:
  // The arrays in RestMesh's order, as one sequence of values: positions
  // (3·n), faces (3·F), uploaded ids (n, or none).
  void write_next() {
    const Hierarchy& h = session_->assets().hierarchy();
    const std::span<const std::uint32_t> ids = session_->uploaded_ids();
    const std::size_t positions = 3 * h.vertex_count(), faces = 3 * h.original_face_count();
    const std::size_t total = positions + faces + ids.size();
    if (sent_ == total) return Finish(grpc::Status::OK);
    part_.Clear();
    const std::size_t end = std::min(total, sent_ + kPartValues);
    for (std::size_t i = sent_; i < std::min(end, positions); ++i) part_.add_positions(static_cast<float>(h.rest_positions[i / 3][i % 3]));
    for (std::size_t i = std::max(sent_, positions); i < std::min(end, positions + faces); ++i) {
      const std::size_t f = i - positions;
      part_.add_faces(h.original_faces[f / 3][f % 3]);
    }
    for (std::size_t i = std::max(sent_, positions + faces); i < end; ++i) part_.add_uploaded_ids(ids[i - positions - faces]);
    sent_ = end;
    StartWrite(&part_);
  }

  std::shared_ptr<Session> session_;
  v1::RestMeshPart part_;
  std::size_t sent_ = 0;  // values of the sequence written
};

}  // namespace

grpc::ServerWriteReactor<v1::RestMeshPart>* new_rest_mesh_reactor(FiligreeService& service,
                                                                  grpc::CallbackServerContext* context,
                                                                  const v1::GetRestMeshRequest& request) {
  return new RestMeshReactor(service, context, request);
}

}  // namespace filigree::server
