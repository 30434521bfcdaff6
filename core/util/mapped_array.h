#pragma once
// A contiguous array that either owns its elements (a std::vector) or reads
// them in place from storage someone else keeps alive (a memory-mapped
// file, held by a shared handle): what lets a loaded hierarchy use its
// file's pages instead of copying them (issue 10).
//
// Reading is the same either way. Growing (push_back, insert, assign, ...)
// and writing elements (edit()) first copy a viewed array into its own
// vector, so a view is never written through; there is deliberately no
// non-const operator[], so that reading through a non-const array never
// copies by accident.
#include <algorithm>
#include <cstddef>
#include <initializer_list>
#include <memory>
#include <span>
#include <stdexcept>
#include <utility>
#include <vector>

namespace filigree {

template <class T>
class MappedArray {
 public:
  using value_type = T;
  using size_type = std::size_t;
  using const_iterator = const T*;
  using iterator = const T*;

  MappedArray() = default;
  MappedArray(std::vector<T> v) : own_(std::move(v)) { sync(); }  // NOLINT: a vector is an owned array
  MappedArray(std::initializer_list<T> v) : own_(v) { sync(); }
  // Views `data` in place; `keeper` keeps the memory alive as long as this
  // array (or any copy of it) views it. Throws std::invalid_argument for a
  // null keeper (nothing would keep the memory alive).
  static MappedArray view(std::span<const T> data, std::shared_ptr<const void> keeper) {
    if (!keeper) throw std::invalid_argument("MappedArray::view needs a keeper for the memory it views");
    MappedArray a;
    a.keeper_ = std::move(keeper);
    a.data_ = data.data();
    a.size_ = data.size();
    return a;
  }

  // Copies of a view view the same memory (and keep it alive); copies of an
  // owned array own a copy.
  MappedArray(const MappedArray& o) : own_(o.own_), keeper_(o.keeper_) { adopt(o); }
  MappedArray(MappedArray&& o) noexcept : own_(std::move(o.own_)), keeper_(std::move(o.keeper_)) {
    adopt(o);
    o.own_.clear(), o.sync();
  }
  MappedArray& operator=(const MappedArray& o) {
    if (this != &o) *this = MappedArray(o);
    return *this;
  }
  MappedArray& operator=(MappedArray&& o) noexcept {
    if (this != &o) {
      own_ = std::move(o.own_);
      keeper_ = std::move(o.keeper_);
      adopt(o);
      o.own_.clear(), o.keeper_.reset(), o.sync();
    }
    return *this;
  }
  MappedArray& operator=(std::initializer_list<T> v) { return *this = std::vector<T>(v); }
  MappedArray& operator=(std::vector<T> v) {
    own_ = std::move(v);
    clear_view(), sync();
    return *this;
  }

  // ---- Reading.
  bool viewing() const { return keeper_ != nullptr; }
  std::size_t size() const { return size_; }
  bool empty() const { return size_ == 0; }
  const T* data() const { return data_; }
  const T& operator[](std::size_t i) const { return data_[i]; }
  const T* begin() const { return data_; }
  const T* end() const { return data_ + size_; }
  const T& back() const { return data_[size_ - 1]; }
  operator std::span<const T>() const { return {data_, size_}; }  // NOLINT: reads as a span anywhere
  std::vector<T> to_vector() const { return {begin(), end()}; }
  // Bytes this array holds: its vector's capacity, or the bytes it views.
  std::size_t bytes() const { return (viewing() ? size_ : own_.capacity()) * sizeof(T); }

  friend bool operator==(const MappedArray& a, std::span<const T> b) { return std::equal(a.begin(), a.end(), b.begin(), b.end()); }
  friend bool operator==(const MappedArray& a, const MappedArray& b) { return a == std::span<const T>(b); }
  friend bool operator==(const MappedArray& a, const std::vector<T>& b) { return a == std::span<const T>(b); }

  // ---- Writing: a view is first copied into this array's own vector.
  std::span<T> edit() {
    own();
    return own_;
  }
  // By value: `x` may be an element of this view, which own() may release.
  void push_back(T x) { own(), own_.push_back(std::move(x)), sync(); }
  // [first, last) may lie in this view, not in an owned array's own vector
  // (std::vector::insert's rule).
  template <class It>
  void insert_back(It first, It last) {
    const std::shared_ptr<const void> keep = keeper_;  // the range stays readable while it is copied
    own(), own_.insert(own_.end(), first, last), sync();
  }
  void reserve(std::size_t n) { own(), own_.reserve(n), sync(); }

 private:
  void own() {
    if (!viewing()) return;
    own_.assign(data_, data_ + size_);
    clear_view(), sync();
  }
  void clear_view() { keeper_.reset(); }
  void sync() { data_ = own_.data(), size_ = own_.size(); }
  // After own_ and keeper_ were taken from `o`: its view, or our own vector.
  void adopt(const MappedArray& o) {
    if (keeper_) data_ = o.data_, size_ = o.size_;
    else sync();
  }

  std::vector<T> own_;
  std::shared_ptr<const void> keeper_;  // non-null: data_ views memory it keeps alive
  const T* data_ = nullptr;
  std::size_t size_ = 0;
};

}  // namespace filigree
