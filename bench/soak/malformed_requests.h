#pragma once
// Requests the server must refuse, mixed into the load on a connection of
// their own: one every few tens of milliseconds, each kind in turn, against
// each session in turn. Each kind has the one status code the server gives
// it (server/filigree_service.cpp, proto/filigree/v1/filigree.proto's error
// list); any other code, or a success, is a failure. Raw stubs with a
// deadline: a server that hangs on one must fail the soak, not stall it.

#include <chrono>
#include <condition_variable>
#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include <grpcpp/grpcpp.h>

#include "bench/soak/failures.h"
#include "filigree/client.h"

namespace filigree::soak {

struct MalformedTally {
  std::string kind;
  grpc::StatusCode expected;
  std::map<grpc::StatusCode, std::uint64_t> got;  // code → count
  std::uint64_t sent = 0;
};

class MalformedRequests {
 public:
  // `sessions` outlive this.
  MalformedRequests(const std::string& address, const std::vector<const SessionHandle*>& sessions,
                    std::chrono::milliseconds every, Failures& failures);
  ~MalformedRequests();
  void start();
  void stop();  // returns once the request in flight has its answer
  std::vector<MalformedTally> tallies() const;

 private:
  void run();
  // One request of kind `kind` (an index into the kinds) against `session`; returns its status.
  grpc::Status send(std::size_t kind, const SessionHandle& session);
  static std::size_t kinds();

  std::shared_ptr<grpc::Channel> channel_;
  std::unique_ptr<v1::Filigree::Stub> stub_;
  const std::vector<const SessionHandle*> sessions_;
  const std::chrono::milliseconds every_;
  Failures& failures_;
  const std::string bad_token_;  // random; never printed
  std::size_t bad_mesh_turn_ = 0;  // which malformed mesh goes next (run()'s thread)

  mutable std::mutex mutex_;
  std::condition_variable stop_cv_;
  bool stopping_ = false;
  std::vector<MalformedTally> tallies_;
  std::thread thread_;
};

}  // namespace filigree::soak
