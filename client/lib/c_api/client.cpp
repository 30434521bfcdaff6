// filigree_connect and the client handle.

#include "c_api/internal.h"

namespace filigree::c_api {
namespace {

std::shared_ptr<grpc::ChannelCredentials> tls_credentials(const filigree_connect_options& options) {
  if ((options.pem_cert_chain == nullptr) != (options.pem_private_key == nullptr))
    throw std::invalid_argument("a client certificate needs both pem_cert_chain and pem_private_key");
  grpc::SslCredentialsOptions ssl;
  if (options.pem_root_certs) ssl.pem_root_certs = options.pem_root_certs;
  if (options.pem_cert_chain) ssl.pem_cert_chain = options.pem_cert_chain;
  if (options.pem_private_key) ssl.pem_private_key = options.pem_private_key;
  return grpc::SslCredentials(ssl);
}

}  // namespace
}  // namespace filigree::c_api

using namespace filigree::c_api;

extern "C" {

int filigree_connect(const char* target, const filigree_connect_options* options, filigree_client** out) {
  constexpr const char* kFunction = "filigree_connect";
  if (!out) return null_argument(nullptr, kFunction, "out");
  *out = nullptr;
  if (!target) return null_argument(nullptr, kFunction, "target");
  return guarded(nullptr, kFunction, [&]() -> int {
    if (!*target) throw std::invalid_argument("the target is empty");
    auto handle = std::make_unique<filigree_client>();
    handle->connection = options ? std::make_shared<Connection>(target, tls_credentials(*options))
                                 : std::make_shared<Connection>(std::string(target));
    return hand_out(std::move(handle), out);
  });
}

int filigree_client_set_decode_threads(filigree_client* client, uint32_t threads) {
  return with_handle(client, "filigree_client_set_decode_threads", [&](filigree_client& c) -> int {
    c.connection->decode_threads = threads;
    return FILIGREE_OK;
  });
}

int filigree_client_set_api_key(filigree_client* client, const char* api_key) {
  return with_handle(client, "filigree_client_set_api_key", [&](filigree_client& c) -> int {
    c.connection->client.set_api_key(api_key ? api_key : "");
    return FILIGREE_OK;
  });
}

const char* filigree_client_last_error(const filigree_client* client) {
  return is_handle(client, filigree_client::kKind) ? client->error.get() : invalid_handle_message();
}

int filigree_client_free(filigree_client* client) {
  if (!client) return FILIGREE_OK;
  if (!unregister_handle(client, filigree_client::kKind))
    return fail(nullptr, FILIGREE_ERROR_INVALID_HANDLE,
                "filigree_client_free: not a live filigree_client (freed, or another kind of handle)");
  delete client;
  return FILIGREE_OK;
}

}  // extern "C"
