// MappedArray: owned, or a view of memory kept alive by a handle, copied on
// the first write (util/mapped_array.h).

#include <memory>
#include <vector>

#include <gtest/gtest.h>

#include "util/mapped_array.h"

namespace filigree {
namespace {

// Memory a view reads, and a handle that keeps it alive.
struct Storage {
  std::shared_ptr<std::vector<int>> values = std::make_shared<std::vector<int>>(std::vector<int>{1, 2, 3, 4});
  std::span<const int> span() const { return *values; }
};

TEST(MappedArray, AViewReadsInPlaceAndKeepsItsStorageAlive) {
  Storage s;
  std::weak_ptr<std::vector<int>> alive = s.values;
  MappedArray<int> a = MappedArray<int>::view(s.span(), s.values);
  EXPECT_TRUE(a.viewing());
  EXPECT_EQ(a.data(), s.values->data());  // no copy
  const MappedArray<int> copy = a;         // a copy views the same memory
  EXPECT_TRUE(copy.viewing());
  EXPECT_EQ(copy.data(), s.values->data());
  EXPECT_EQ(a.bytes(), 4 * sizeof(int));
  s.values.reset();
  EXPECT_FALSE(alive.expired());
  a = std::vector<int>{7};  // a owns now; the copy still views
  EXPECT_FALSE(a.viewing());
  EXPECT_FALSE(alive.expired());
  EXPECT_EQ(copy, (std::vector<int>{1, 2, 3, 4}));
}

TEST(MappedArray, AViewNeedsAKeeper) {
  const std::vector<int> values = {1, 2};
  EXPECT_THROW(MappedArray<int>::view(values, nullptr), std::invalid_argument);
}

TEST(MappedArray, GrowingAViewFromItsOwnElementsReadsThemBeforeReleasingThem) {
  Storage s;
  MappedArray<int> a = MappedArray<int>::view(s.span(), s.values);
  s.values.reset();  // a holds the last reference
  a.push_back(a[1]);
  EXPECT_EQ(a, (std::vector<int>{1, 2, 3, 4, 2}));
  Storage t;
  MappedArray<int> b = MappedArray<int>::view(t.span(), t.values);
  t.values.reset();
  b.insert_back(b.begin(), b.begin() + 2);
  EXPECT_EQ(b, (std::vector<int>{1, 2, 3, 4, 1, 2}));
}

TEST(MappedArray, TheLastViewGoneFreesTheStorage) {
  Storage s;
  std::weak_ptr<std::vector<int>> alive = s.values;
  {
    MappedArray<int> a = MappedArray<int>::view(s.span(), s.values);
    MappedArray<int> moved = std::move(a);
    EXPECT_TRUE(moved.viewing());
    EXPECT_FALSE(a.viewing());  // NOLINT: moved-from is empty by contract
    EXPECT_TRUE(a.empty());
    s.values.reset();
    EXPECT_FALSE(alive.expired());
  }
  EXPECT_TRUE(alive.expired());
}

TEST(MappedArray, WritingAViewCopiesItFirstAndLeavesTheStorageAlone) {
  Storage s;
  MappedArray<int> a = MappedArray<int>::view(s.span(), s.values);
  a.edit()[1] = 20;
  EXPECT_FALSE(a.viewing());
  EXPECT_NE(a.data(), s.values->data());
  EXPECT_EQ(a, (std::vector<int>{1, 20, 3, 4}));
  EXPECT_EQ(*s.values, (std::vector<int>{1, 2, 3, 4}));

  MappedArray<int> b = MappedArray<int>::view(s.span(), s.values);
  b.push_back(5);
  EXPECT_EQ(b, (std::vector<int>{1, 2, 3, 4, 5}));
  MappedArray<int> c = MappedArray<int>::view(s.span(), s.values);
  c.reserve(16);  // owns now, its elements copied
  EXPECT_FALSE(c.viewing());
  EXPECT_EQ(c, (std::vector<int>{1, 2, 3, 4}));
  EXPECT_EQ(*s.values, (std::vector<int>{1, 2, 3, 4}));
}

TEST(MappedArray, OwnedCopiesAreIndependent) {
  MappedArray<int> a = {1, 2, 3};
  MappedArray<int> b = a;
  b.edit()[0] = 9;
  EXPECT_EQ(a, (std::vector<int>{1, 2, 3}));
  EXPECT_EQ(b, (std::vector<int>{9, 2, 3}));
  MappedArray<int> c = std::move(b);
  EXPECT_EQ(c, (std::vector<int>{9, 2, 3}));
  EXPECT_TRUE(b.empty());  // NOLINT: moved-from is empty by contract
  c.insert_back(a.begin(), a.end());
  EXPECT_EQ(c, (std::vector<int>{9, 2, 3, 1, 2, 3}));
  const std::span<const int> view = c;
  EXPECT_EQ(view.size(), 6u);
  EXPECT_EQ(view.data(), c.data());
}

}  // namespace
}  // namespace filigree
