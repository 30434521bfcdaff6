#pragma once
// An indexed binary heap of hierarchy nodes for the cut's priority queues
// (thesis §3.3): each node's place is kept, so re-scoring or leaving the queue
// is O(log n) in place. A lazy queue that pushes a new entry per re-score
// would keep every stale entry below its top for as long as the session
// lives; this one holds each node at most once. Keys live in the entries, so
// sifting reads only the heap's own array.

#include <cstdint>
#include <vector>

#include "hierarchy/hierarchy.h"

namespace filigree {

struct HeapEntry {
  float key;
  NodeId node;
};

// `Before(a, b)`: entry a comes out before entry b (a strict weak order).
// `place` is the node → slot map, shared by heaps that never hold the same
// node at once; kNone marks "in none".
template <class Before>
class NodeHeap {
 public:
  NodeHeap(std::vector<Index>& place, Before before = {}) : place_(&place), before_(before) {}

  bool empty() const { return entries_.empty(); }
  std::size_t size() const { return entries_.size(); }
  const HeapEntry& top() const { return entries_.front(); }
  bool contains(NodeId k) const {
    const Index p = (*place_)[k];
    return p < entries_.size() && entries_[p].node == k;
  }

  void push(NodeId k, float key) {
    entries_.push_back({key, k});
    up(entries_.size() - 1);
  }
  // Gives k a new key. Precondition: contains(k).
  void update(NodeId k, float key) {
    const std::size_t p = (*place_)[k];
    entries_[p].key = key;
    if (!up(p)) down(p);
  }
  // Precondition: contains(k).
  void erase(NodeId k) {
    const std::size_t p = (*place_)[k];
    (*place_)[k] = kNone;
    const HeapEntry last = entries_.back();
    entries_.pop_back();
    if (p == entries_.size()) return;
    entries_[p] = last;
    if (!up(p)) down(p);
  }
  void release() {
    for (const HeapEntry& e : entries_) (*place_)[e.node] = kNone;
    std::vector<HeapEntry>().swap(entries_);  // assigning {} would keep the capacity
  }
  std::size_t memory_bytes() const { return entries_.capacity() * sizeof(HeapEntry); }

 private:
  // Both leave entry p's final slot in place_; up() says whether it moved.
  bool up(std::size_t p) {
    const HeapEntry e = entries_[p];
    const std::size_t start = p;
    while (p > 0) {
      const std::size_t parent = (p - 1) / 2;
      if (!before_(e, entries_[parent])) break;
      entries_[p] = entries_[parent];
      (*place_)[entries_[p].node] = static_cast<Index>(p);
      p = parent;
    }
    entries_[p] = e;
    (*place_)[e.node] = static_cast<Index>(p);
    return p != start;
  }
  void down(std::size_t p) {
    const HeapEntry e = entries_[p];
    const std::size_t n = entries_.size();
    while (true) {
      std::size_t child = 2 * p + 1;
      if (child >= n) break;
      if (child + 1 < n && before_(entries_[child + 1], entries_[child])) ++child;
      if (!before_(entries_[child], e)) break;
      entries_[p] = entries_[child];
      (*place_)[entries_[p].node] = static_cast<Index>(p);
      p = child;
    }
    entries_[p] = e;
    (*place_)[e.node] = static_cast<Index>(p);
  }

  std::vector<Index>* place_;
  Before before_;
  std::vector<HeapEntry> entries_;
};

}  // namespace filigree
