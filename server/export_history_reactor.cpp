#include "server/export_history_reactor.h"

#include <algorithm>
#include <cmath>
#include <memory>
#include <utility>
#include <vector>

#include "codec/delta_codec.h"
#include "codec/delta_quantization.h"
#include "hierarchy/hierarchy.h"
#include "runtime/deformer.h"
#include "runtime/pose.h"
#include "server/filigree_service.h"
#include "server/session.h"

namespace filigree::server {
namespace {

// The most entries one call exports (each a full-detail frame).
constexpr std::size_t kMostExported = 2000;

// Each state is deformed (on a job: at 1.25M vertices a frame is tens of
// ms) when the previous one is written, so a call holds one frame.
class ExportHistoryReactor final : public grpc::ServerWriteReactor<v1::HistoryFrame> {
 public:
  ExportHistoryReactor(FiligreeService& service, grpc::CallbackServerContext* context, const v1::ExportHistoryRequest& request)
      : service_(service) {
    const std::uint64_t from = request.from_entry(), to = request.to_entry();
    service.with_session(*context, request.session_id(), Role::kViewer, [this, from, to](grpc::Status status, std::shared_ptr<Session> s) {
      if (!status.ok()) return Finish(status);
      if (to != 0 && to < from) return Finish({grpc::StatusCode::INVALID_ARGUMENT, "to_entry is before from_entry"});
      // Counted as one of the session's streams, and as one of the exports
      // the server runs at once (each keeps a thread deforming).
      if (const grpc::Status admitted = service_.open_stream(*s, &stream_slot_); !admitted.ok()) return Finish(admitted);
      export_slot_ = service_.take_export_slot();
      if (!export_slot_)
        return Finish({grpc::StatusCode::RESOURCE_EXHAUSTED,
                       "as many history exports as this server has cores are running: retry when one ends"});
      session_ = std::move(s);
      states_ = session_->history_states(from, to);
      if (states_.size() > kMostExported)
        return Finish({grpc::StatusCode::INVALID_ARGUMENT, "the range holds " + std::to_string(states_.size()) +
                                                               " entries; export at most " + std::to_string(kMostExported) +
                                                               " at a time"});
      write_next();
    });
  }

  void OnWriteDone(bool ok) override {
    if (!ok) return Finish(grpc::Status::CANCELLED);
    write_next();
  }
  void OnDone() override { delete this; }

 private:
  void write_next() {
    if (next_ == states_.size()) return Finish(grpc::Status::OK);
    service_.run_job(
        [this] {
          try {
            make(states_[next_]);
          } catch (const std::exception& e) {
            return Finish({grpc::StatusCode::INTERNAL, std::string("the history's state could not be deformed: ") + e.what()});
          }
          ++next_;
          StartWrite(&message_);
        },
        [this](const grpc::Status& why) { Finish(why); });
  }

  // The message for the state after one entry: its base pose deformed by
  // direct recovery (T = 0, a function of the pose alone) and encoded as one
  // buffer within the session's error target.
  void make(const std::pair<v1::HistoryEntry, std::vector<float>>& state) {
    const SessionAssets& assets = session_->assets();
    const Hierarchy& h = assets.hierarchy();
    if (!deformer_) deformer_ = std::make_unique<Deformer>(assets.model, DeformerOptions{});
    Pose pose;
    const std::vector<float>& base = state.second;
    for (std::size_t i = 0; 3 * i < base.size(); ++i) pose.positions.emplace_back(base[3 * i], base[3 * i + 1], base[3 * i + 2]);
    positions_.resize(h.vertex_count());
    (void)deformer_->deform(pose, positions_);
    std::vector<Vec3> deltas(h.vertex_count());
    double range = 0.0;
    for (std::size_t v = 0; v < deltas.size(); ++v) {
      deltas[v] = positions_[v] - h.rest_positions[v];
      range = std::max(range, deltas[v].cwiseAbs().maxCoeff());
    }
    const std::uint32_t bits = std::clamp<std::uint32_t>(bits_for_error(2.0 * range, assets.automatic_max_error), 8, 24);
    const EncodedDeltas encoded = encode_deltas(deltas, bits);
    message_.Clear();
    message_.set_entry(state.first.seq());
    message_.set_author(state.first.author());
    message_.set_time(state.first.end_time());
    message_.mutable_base_pose()->Add(base.begin(), base.end());
    v1::Frame& f = *message_.mutable_frame();
    f.set_version(state.first.version());
    f.set_vertex_count(static_cast<std::uint32_t>(h.vertex_count()));
    f.set_deltas(encoded.bytes);
    f.set_quantization_bits(encoded.bits);
    f.set_delta_min(encoded.min);
    f.set_delta_range(encoded.range);
    f.set_max_error(encoded.max_error);
  }

  FiligreeService& service_;
  std::shared_ptr<void> stream_slot_, export_slot_;
  std::shared_ptr<Session> session_;
  std::vector<std::pair<v1::HistoryEntry, std::vector<float>>> states_;
  std::size_t next_ = 0;
  std::unique_ptr<Deformer> deformer_;
  std::vector<Vec3> positions_;
  v1::HistoryFrame message_;
};

}  // namespace

grpc::ServerWriteReactor<v1::HistoryFrame>* new_export_history_reactor(FiligreeService& service,
                                                                       grpc::CallbackServerContext* context,
                                                                       const v1::ExportHistoryRequest& request) {
  return new ExportHistoryReactor(service, context, request);
}

}  // namespace filigree::server
