#pragma once
// Turns at some work, at most `limit` held at once; a thread that asks for
// one waits until one is free. Preprocessing uploads and loading sessions
// take turns (FiligreeService), so that a burst of either does not start
// all of them at once.

#include <condition_variable>
#include <cstddef>
#include <mutex>

namespace filigree::server {

class Turns {
 public:
  explicit Turns(unsigned limit);  // limit 0 is taken as 1

  // Waits for a free turn and holds it until release().
  void acquire();
  void release();
  // Threads waiting in acquire() now.
  std::size_t waiting() const;

 private:
  const unsigned limit_;
  mutable std::mutex mutex_;
  std::condition_variable freed_;
  unsigned held_ = 0;
  std::size_t waiting_ = 0;
};

}  // namespace filigree::server
