#include "server/bounded_status.h"

namespace filigree::server {
namespace {

class BoundedStatus final : public grpc::experimental::Interceptor {
 public:
  void Intercept(grpc::experimental::InterceptorBatchMethods* methods) override {
    if (methods->QueryInterceptionHookPoint(grpc::experimental::InterceptionHookPoints::PRE_SEND_STATUS)) {
      const grpc::Status status = methods->GetSendStatus();
      if (status.error_message().size() > kMaxStatusMessageBytes)
        methods->ModifySendStatus(
            grpc::Status(status.error_code(), bounded_message(status.error_message()), status.error_details()));
    }
    methods->Proceed();
  }
};

class BoundedStatusFactory final : public grpc::experimental::ServerInterceptorFactoryInterface {
 public:
  grpc::experimental::Interceptor* CreateServerInterceptor(grpc::experimental::ServerRpcInfo*) override {
    return new BoundedStatus;
  }
};

}  // namespace

std::string bounded_message(const std::string& message, std::size_t limit) {
  if (message.size() <= limit) return message;
  static const std::string kMark = "…";  // 3 bytes
  if (limit < kMark.size()) return message.substr(0, 0);
  std::size_t cut = limit - kMark.size();
  // Back off continuation bytes (10xxxxxx): the cut falls before a sequence's first byte.
  while (cut > 0 && (static_cast<unsigned char>(message[cut]) & 0xC0) == 0x80) --cut;
  return message.substr(0, cut) + kMark;
}

std::unique_ptr<grpc::experimental::ServerInterceptorFactoryInterface> bounded_status_interceptors() {
  return std::make_unique<BoundedStatusFactory>();
}

}  // namespace filigree::server
