#pragma once
// A session's history as states (Client::export_history): the base pose
// after each entry of a range and the detailed mesh it deforms to, oldest
// first, decoded from the server's ExportHistory stream.

#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <grpcpp/grpcpp.h>

#include "filigree/call_metadata.h"
#include "filigree/frame_decoder.h"
#include "filigree/history_state.h"
#include "filigree/v1/filigree.grpc.pb.h"

namespace filigree {

// The server deforms one state at a time, as it is read. Not reconnected:
// after a failure, export the rest again (from the entry after the last
// one read). cancel() may be called from any thread; finish() once no
// other thread is inside read().
class HistoryExport {
 public:
  HistoryExport(const HistoryExport&) = delete;
  HistoryExport& operator=(const HistoryExport&) = delete;
  // Cancels the stream if finish() was not called.
  ~HistoryExport();

  // Blocks for the next state; nullopt once the stream has ended (every
  // state read, cancelled, error: finish() says which). Throws ClientError
  // (DATA_LOSS) for a state whose frame does not decode against the rest
  // mesh; the stream is then cancelled.
  std::optional<HistoryState> read();

  // Ends the stream at once (thread-safe, any time).
  void cancel();

  // Discards unread states and returns the call's status (OK once every
  // state of the range was sent; INVALID_ARGUMENT for a range the server
  // refused, e.g. `to` before `from`; CANCELLED after cancel()).
  grpc::Status finish();

 private:
  friend class Client;
  HistoryExport(v1::Filigree::Stub& stub, const v1::ExportHistoryRequest& request, const std::string& token,
                Routing routing, std::vector<float> rest_positions);

  FrameDecoder decoder_;
  grpc::ClientContext context_;  // TryCancel is thread-safe
  std::unique_ptr<grpc::ClientReader<v1::HistoryFrame>> stream_;
  std::optional<grpc::Status> status_;  // set once the stream has ended
};

}  // namespace filigree
