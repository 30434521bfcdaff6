#pragma once
// The C API's handles for working together (filigree.h, "working
// together"): a history read, a presence stream, a history export.

#include <cstddef>
#include <memory>
#include <mutex>
#include <optional>
#include <string>

#include "c_api/internal.h"
#include "c_api/presence_feed.h"
#include "filigree/history_export.h"

struct filigree_history {
  static constexpr filigree::c_api::Kind kKind = filigree::c_api::Kind::kHistory;
  static constexpr const char* kName = "filigree_history";
  filigree::v1::History history;  // never changed after the read: no lock
  mutable filigree::c_api::ErrorSlot error;
};

struct filigree_presence {
  static constexpr filigree::c_api::Kind kKind = filigree::c_api::Kind::kPresence;
  static constexpr const char* kName = "filigree_presence";
  std::shared_ptr<filigree::c_api::Connection> connection;
  std::unique_ptr<filigree::c_api::PresenceFeed> feed;
  mutable filigree::c_api::ErrorSlot error;
};

struct filigree_history_export {
  static constexpr filigree::c_api::Kind kKind = filigree::c_api::Kind::kHistoryExport;
  static constexpr const char* kName = "filigree_history_export";
  std::shared_ptr<filigree::c_api::Connection> connection;
  std::size_t float_count = 0;       // 3·n: a state's positions
  std::unique_ptr<filigree::HistoryExport> stream;  // its cancel() is thread-safe; the rest under read_mutex
  std::mutex read_mutex;             // one next() or close() at a time
  mutable std::mutex state_mutex;    // guards the latest state and the end below
  std::optional<filigree::HistoryState> latest;  // the latest state read (its positions moved out)
  bool closed = false;  // close() was called: CANCELLED is a normal end
  bool ended = false;
  filigree::c_api::FrameStream::End end;  // why, once ended
  mutable filigree::c_api::ErrorSlot error;
};
