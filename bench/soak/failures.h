#pragma once
// What went wrong during the soak, reported from any thread: every failure is
// counted; the first ones keep their reason for the summary and are printed
// at once (a 10-minute run should not hide its first failure until the end).

#include <cstddef>
#include <mutex>
#include <string>
#include <vector>

namespace filigree::soak {

class Failures {
 public:
  void add(const std::string& why);
  std::size_t count() const;
  std::vector<std::string> reasons() const;  // the first kKept, in order

 private:
  static constexpr std::size_t kKept = 40;
  mutable std::mutex mutex_;
  std::size_t count_ = 0;
  std::vector<std::string> reasons_;
};

}  // namespace filigree::soak
