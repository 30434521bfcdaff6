// TimeLeft: the time a task has left, from its recent rate.

#include <gtest/gtest.h>

#include "util/time_left.h"

namespace filigree {
namespace {

TEST(TimeLeft, ASteadyTaskHasWhatItsRateSays) {
  TimeLeft left;
  EXPECT_FALSE(left.seconds().has_value());
  for (int k = 0; k <= 50; ++k) left.add(0.2 * k, 0.01 * k);  // 5% a second
  ASSERT_TRUE(left.seconds().has_value());
  EXPECT_NEAR(*left.seconds(), 10.0, 1e-9);  // half left at 5% a second
}

TEST(TimeLeft, ASlowingTaskIsJudgedByItsRecentRate) {
  // 10% a second for the first half, then 2% a second (as simplification
  // slows when the mesh coarsens): the whole run's average would promise 7 s.
  TimeLeft left;
  for (int k = 0; k <= 50; ++k) left.add(0.1 * k, 0.01 * k);
  for (int k = 1; k <= 20; ++k) left.add(5.0 + 0.5 * k, 0.5 + 0.01 * k);
  ASSERT_TRUE(left.seconds().has_value());
  EXPECT_NEAR(*left.seconds(), 15.0, 1e-9);  // 30% left at 2% a second
}

TEST(TimeLeft, ACostThatGrowsWithTheFractionIsEstimatedExactly) {
  // Seconds per unit of work 10 + 20·f: t(f) = 10 f + 10 f², 12.5 s left at half.
  TimeLeft left;
  for (int k = 0; k <= 50; ++k) {
    const double f = 0.01 * k;
    left.add(10.0 * f + 10.0 * f * f, f);
  }
  ASSERT_TRUE(left.seconds().has_value());
  EXPECT_NEAR(*left.seconds(), 12.5, 1e-6);
}

TEST(TimeLeft, NoEstimateTooEarlyOrWhileNothingMoves) {
  TimeLeft early;
  early.add(0.0, 0.0);
  early.add(0.3, 0.015);  // 1.5% and 0.3 s: too little to go by
  EXPECT_FALSE(early.seconds().has_value());
  TimeLeft stuck;
  stuck.add(0.0, 0.3);
  stuck.add(2.0, 0.3);
  EXPECT_FALSE(stuck.seconds().has_value());
}

}  // namespace
}  // namespace filigree
