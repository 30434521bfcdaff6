// --max-streams-per-connection, end to end against a filigree-server child:
// a connection at its limit carries no further call until one of its calls
// ends (the client queues it; nothing fails), while another connection is
// served at once; and browsers are not bound by it together (gRPC-Web calls
// reach the service over one in-process channel, which has no such limit).
//
// No timing: the queued Watch is shown waiting by a Watch on another
// connection getting its first frame first, and shown served by its own
// first frame arriving once another call is cancelled, under a generous
// deadline.

#include <chrono>
#include <future>
#include <memory>
#include <string>
#include <vector>

#include <grpcpp/grpcpp.h>
#include <gtest/gtest.h>

#include "filigree/v1/filigree.grpc.pb.h"
#include "support/raw_socket.h"
#include "support/server_process.h"
#include "support/grpc_upload.h"
#include "support/test_meshes.h"

namespace filigree {
namespace {

using namespace std::chrono_literals;
using test::Clock;
using test::ServerProcess;

constexpr auto kPatience = 30s;  // for what must happen; nothing here should take a second

// A channel with a connection of its own: channels with the same arguments
// share connections through gRPC's global subchannel pool otherwise.
std::shared_ptr<grpc::Channel> own_connection(const std::string& address) {
  grpc::ChannelArguments args;
  args.SetInt(GRPC_ARG_USE_LOCAL_SUBCHANNEL_POOL, 1);
  return grpc::CreateCustomChannel(address, grpc::InsecureChannelCredentials(), args);
}

struct Session {
  std::string id, viewer_token;
};

Session upload(v1::Filigree::Stub& stub) {
  const test::Uploaded made = test::upload_mesh(stub, test::file_bytes(test::shipped_path("bunny_small.obj")), "obj", 150);
  EXPECT_TRUE(made.status.ok()) << made.status.error_message();
  return {made.created.info().session_id(), made.created.viewer_token()};
}

// One Watch call: opened, and its first frame (the session's current one) read.
class Watch {
 public:
  Watch(v1::Filigree::Stub& stub, const Session& s) {
    context_.AddMetadata("x-filigree-token", s.viewer_token);
    context_.AddMetadata("x-session-id", s.id);
    v1::WatchRequest request;
    request.set_session_id(s.id);
    reader_ = stub.Watch(&context_, request);
  }
  bool first_frame() {
    v1::Frame frame;
    return reader_->Read(&frame);
  }
  // Ends the call from the client's side.
  grpc::Status cancel() {
    context_.TryCancel();
    return reader_->Finish();
  }

 private:
  grpc::ClientContext context_;
  std::unique_ptr<grpc::ClientReader<v1::Frame>> reader_;
};

TEST(GrpcStreamLimits, AConnectionAtItsLimitQueuesTheNextCallUntilOneEndsAndOthersAreServed) {
  ServerProcess server(FILIGREE_SERVER_BINARY, {"--max-streams-per-connection", "2"});
  const Session session = upload(*v1::Filigree::NewStub(own_connection(server.address())));
  ASSERT_FALSE(session.id.empty());

  auto a = v1::Filigree::NewStub(own_connection(server.address()));
  Watch first(*a, session), second(*a, session);
  ASSERT_TRUE(first.first_frame());
  ASSERT_TRUE(second.first_frame());  // connection A now holds its 2 calls

  // A third Watch on A: in a thread, since the call waits for room on the
  // connection. Its context is ours, to cancel it however the test ends.
  grpc::ClientContext third_context;
  third_context.AddMetadata("x-filigree-token", session.viewer_token);
  third_context.AddMetadata("x-session-id", session.id);
  auto third = std::async(std::launch::async, [&] {
    v1::WatchRequest request;
    request.set_session_id(session.id);
    auto reader = a->Watch(&third_context, request);
    v1::Frame frame;
    const bool got = reader->Read(&frame);
    third_context.TryCancel();
    reader->Finish();
    return got;
  });
  struct CancelThird {
    grpc::ClientContext& c;
    ~CancelThird() { c.TryCancel(); }  // before `third`'s destructor waits for its thread
  } cancel_third{third_context};

  // A Watch on connection B, opened after the third one, is served at once...
  auto b = v1::Filigree::NewStub(own_connection(server.address()));
  Watch other(*b, session);
  ASSERT_TRUE(other.first_frame());
  // ...while the third on A still has nothing (it cannot, while A is full).
  EXPECT_NE(third.wait_for(0s), std::future_status::ready) << "connection A carried a third call";

  // The first call on A ends: the third starts and gets its frame.
  EXPECT_EQ(first.cancel().error_code(), grpc::StatusCode::CANCELLED);
  ASSERT_EQ(third.wait_for(kPatience), std::future_status::ready) << "the third call never started";
  EXPECT_TRUE(third.get());

  // A and B keep working.
  EXPECT_EQ(second.cancel().error_code(), grpc::StatusCode::CANCELLED);
  EXPECT_EQ(other.cancel().error_code(), grpc::StatusCode::CANCELLED);
}

// The response so far holds a whole gRPC-Web data frame (flag 0) in its
// chunked body.
bool has_data_frame(const std::string& bytes) {
  std::size_t at = bytes.find("\r\n\r\n");
  if (at == std::string::npos) return false;
  at += 4;
  std::string body;
  for (;;) {
    const std::size_t line_end = bytes.find("\r\n", at);
    if (line_end == std::string::npos) break;
    const std::size_t size = std::stoul(bytes.substr(at, line_end - at), nullptr, 16);
    if (size == 0 || bytes.size() < line_end + 2 + size) break;
    body += bytes.substr(line_end + 2, size);
    at = line_end + 2 + size + 2;
  }
  if (body.size() < 5 || body[0] != 0) return false;
  std::size_t n = 0;
  for (int i = 1; i < 5; ++i) n = (n << 8) | static_cast<unsigned char>(body[i]);
  return body.size() >= 5 + n;
}

TEST(GrpcStreamLimits, BrowserCallsAreNotBoundTogetherByIt) {
  ServerProcess server(FILIGREE_SERVER_BINARY, {"--max-streams-per-connection", "2"}, /*http=*/true);
  const Session session = upload(*v1::Filigree::NewStub(own_connection(server.address())));
  ASSERT_FALSE(session.id.empty());

  v1::WatchRequest request;
  request.set_session_id(session.id);
  const std::string message = request.SerializeAsString();
  std::string frame(1, '\0');
  for (int shift : {24, 16, 8, 0}) frame += static_cast<char>((message.size() >> shift) & 0xff);
  frame += message;
  const std::string post = "POST /filigree.v1.Filigree/Watch HTTP/1.1\r\nHost: localhost\r\n"
                           "Content-Type: application/grpc-web+proto\r\nX-Grpc-Web: 1\r\n"
                           "X-Filigree-Token: " + session.viewer_token + "\r\nX-Session-Id: " + session.id +
                           "\r\nContent-Length: " + std::to_string(frame.size()) + "\r\n\r\n" + frame;
  // Three browsers, each its own HTTP connection, all through the one
  // in-process channel: each gets its first frame while the others stay open.
  std::vector<std::unique_ptr<test::RawSocket>> browsers;
  for (int i = 0; i < 3; ++i) {
    browsers.push_back(std::make_unique<test::RawSocket>(server.http_address()));
    ASSERT_TRUE(browsers.back()->send(post));
    EXPECT_TRUE(browsers.back()->read_until(has_data_frame, Clock::now() + kPatience))
        << "browser " << i << " got: " << browsers.back()->received().substr(0, 200);
  }
}

}  // namespace
}  // namespace filigree
