#pragma once
// One Redis reply as the store reads it: hiredis' reply tree copied into
// owned values, so nothing of hiredis leaks past the connection.

#include <string>
#include <vector>

namespace filigree::server {

struct RedisReply {
  enum class Type { kNil, kString, kInteger, kArray, kStatus };
  Type type = Type::kNil;
  std::string str;  // kString, kStatus
  long long integer = 0;
  std::vector<RedisReply> elements;

  bool nil() const { return type == Type::kNil; }
};

}  // namespace filigree::server
