// The HTTP port's gRPC-Web framing: request bodies and grpc-timeout headers.

#include <exception>
#include <string_view>
#include <vector>

#include "fuzz_input.h"
#include "server/http/grpc_web_bridge.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string_view bytes(reinterpret_cast<const char*>(data), size);
  try {
    std::vector<std::string_view> messages;
    (void)filigree::server::http::parse_request_body(bytes, &messages);
    for (const std::string_view message : messages)
      if (!message.empty() && (message.data() < bytes.data() || message.data() + message.size() > bytes.data() + size))
        __builtin_trap();  // every message must lie inside the body
    (void)filigree::server::http::parse_grpc_timeout(bytes.substr(0, 16));
    (void)filigree::server::http::is_grpc_web_binary(bytes);
  } catch (const std::exception&) {
  }
  return 0;
}
