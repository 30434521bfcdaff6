// HelperTeam (util/helper_team.h): a run calls every id once, the caller's
// id 0 on the caller and the others on distinct helper threads; helpers
// reserved by one crew are not handed to another until it is done; many
// callers at once each get whole, correct runs.

#include <atomic>
#include <mutex>
#include <set>
#include <stdexcept>
#include <thread>
#include <vector>

#include <sys/wait.h>
#include <unistd.h>

#include <gtest/gtest.h>

#include "util/helper_team.h"

namespace filigree {
namespace {

TEST(HelperTeam, RunCallsEveryIdOnceOnDistinctThreads) {
  HelperTeam team(3);
  for (int round = 0; round < 200; ++round) {
    HelperTeam::Crew crew = team.reserve(3);
    ASSERT_EQ(crew.threads(), 4u);
    std::vector<int> calls(crew.threads(), 0);
    std::vector<std::thread::id> on(crew.threads());
    crew.run([&](std::size_t id) {
      ++calls[id];  // each id's slot is written by its one call only
      on[id] = std::this_thread::get_id();
    });
    for (std::size_t id = 0; id < calls.size(); ++id) EXPECT_EQ(calls[id], 1) << "id " << id << ", round " << round;
    EXPECT_EQ(on[0], std::this_thread::get_id());
    EXPECT_EQ(std::set<std::thread::id>(on.begin(), on.end()).size(), on.size());
  }
}

TEST(HelperTeam, ReservedHelpersAreNotSharedUntilTheCrewIsDone) {
  HelperTeam team(2);
  {
    HelperTeam::Crew first = team.reserve(1);
    EXPECT_EQ(first.threads(), 2u);
    HelperTeam::Crew second = team.reserve(5);  // only one helper is left
    EXPECT_EQ(second.threads(), 2u);
    HelperTeam::Crew third = team.reserve(1);  // none
    EXPECT_EQ(third.threads(), 1u);
    int called = 0;
    third.run([&](std::size_t id) { called += static_cast<int>(id) + 1; });
    EXPECT_EQ(called, 1);  // the caller alone, as id 0
  }
  EXPECT_EQ(team.reserve(2).threads(), 3u);  // all back once the crews are gone
}

TEST(HelperTeam, ACrewHoldsAtMostItsFixedRoom) {
  HelperTeam team(HelperTeam::kMaxCrew + 2);
  HelperTeam::Crew crew = team.reserve(100);
  ASSERT_EQ(crew.threads(), 1 + HelperTeam::kMaxCrew);
  std::vector<std::atomic<int>> calls(crew.threads());
  crew.run([&](std::size_t id) { calls[id].fetch_add(1); });
  for (std::size_t id = 0; id < calls.size(); ++id) EXPECT_EQ(calls[id].load(), 1) << "id " << id;
  EXPECT_EQ(team.reserve(100).threads(), 3u);  // the two left over
}

TEST(HelperTeam, ACrewRunsOnce) {
  HelperTeam team(1);
  HelperTeam::Crew crew = team.reserve(1);
  crew.run([](std::size_t) {});
  EXPECT_THROW(crew.run([](std::size_t) {}), std::logic_error);
}

TEST(HelperTeam, ManyCallersAtOnceEachGetWholeRuns) {
  HelperTeam team(2);
  constexpr int kCallers = 4, kRuns = 300;
  std::atomic<int> wrong{0}, helped{0};
  std::vector<std::thread> callers;
  for (int c = 0; c < kCallers; ++c)
    callers.emplace_back([&] {
      for (int r = 0; r < kRuns; ++r) {
        HelperTeam::Crew crew = team.reserve(2);
        const std::size_t n = crew.threads();
        std::vector<std::atomic<int>> calls(n);
        crew.run([&](std::size_t id) { calls[id].fetch_add(1); });
        for (std::size_t id = 0; id < n; ++id)
          if (calls[id].load() != 1) wrong.fetch_add(1);
        if (n > 1) helped.fetch_add(1);
      }
    });
  for (std::thread& t : callers) t.join();
  EXPECT_EQ(wrong.load(), 0);
  EXPECT_GT(helped.load(), 0);  // some runs found an idle helper
}

// A forked child has none of the parent's helper threads: its crews are the
// caller alone, and a run still completes (waiting for a helper that is not
// there would hang the child until its alarm kills it).
TEST(HelperTeam, AForkedChildRunsAlone) {
  HelperTeam& team = HelperTeam::shared();
  { HelperTeam::Crew warm = team.reserve(1); warm.run([](std::size_t) {}); }
  const pid_t child = fork();
  ASSERT_GE(child, 0);
  if (child == 0) {
    alarm(20);  // a child that hangs is killed, and the parent sees a signal
    HelperTeam::Crew crew = team.reserve(4);
    int calls = 0;
    crew.run([&](std::size_t) { ++calls; });
    _exit(crew.threads() == 1 && calls == 1 ? 0 : 1);
  }
  int status = 0;
  ASSERT_EQ(waitpid(child, &status, 0), child);
  ASSERT_TRUE(WIFEXITED(status));
  EXPECT_EQ(WEXITSTATUS(status), 0);
}

}  // namespace
}  // namespace filigree
