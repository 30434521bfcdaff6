#pragma once
// An estimate of the time a task has left, from how its fraction done grew.
// Simplification slows as the mesh coarsens, so the whole run's average
// promises too little: the cost of a unit of work is taken from the last
// tenth of it, and its growth from the tenth before (a cost that grows
// linearly with the fraction is estimated exactly).

#include <algorithm>
#include <cstddef>
#include <deque>
#include <optional>
#include <utility>

namespace filigree {

class TimeLeft {
 public:
  // The task is `fraction` (0…1, not decreasing) done after `seconds`.
  void add(double seconds, double fraction) {
    samples_.emplace_back(seconds, fraction);
    // Keep what covers the last two tenths of the work.
    while (samples_.size() > 2 && (samples_[1].second <= fraction - 2 * kWindow || samples_.size() > kMostSamples))
      samples_.pop_front();
  }

  // Seconds left; none before 2% of the work and half a second, or while it
  // has not moved.
  std::optional<double> seconds() const {
    if (samples_.size() < 2) return std::nullopt;
    const auto& [t1, f1] = samples_.back();
    const double f0 = std::max(samples_.front().second, f1 - kWindow);
    if (f1 < 0.02 || t1 < 0.5 || f1 <= f0) return std::nullopt;
    // Seconds per unit of work over the last window, at its middle.
    const double recent = (t1 - time_at(f0)) / (f1 - f0);
    if (!(recent > 0.0)) return std::nullopt;
    double cost = recent, growth = 0.0;
    const double fp = std::max(samples_.front().second, f0 - kWindow);
    if (f0 - fp >= 0.5 * kWindow) {
      // The window before: how fast the cost grows (never taken to shrink).
      const double before = (time_at(f0) - time_at(fp)) / (f0 - fp);
      growth = std::max(0.0, (recent - before) / (0.5 * (f1 - fp)));
      cost = recent + growth * 0.5 * (f1 - f0);  // at f1
    }
    const double rest = 1.0 - f1;
    return cost * rest + 0.5 * growth * rest * rest;
  }

 private:
  // The time at which the task was `fraction` done (linear between samples).
  double time_at(double fraction) const {
    for (std::size_t i = 1; i < samples_.size(); ++i) {
      const auto& [ta, fa] = samples_[i - 1];
      const auto& [tb, fb] = samples_[i];
      if (fb >= fraction) return fb > fa ? ta + (tb - ta) * (fraction - fa) / (fb - fa) : tb;
    }
    return samples_.back().first;
  }

  static constexpr double kWindow = 0.1;
  static constexpr std::size_t kMostSamples = 1024;
  std::deque<std::pair<double, double>> samples_;  // (seconds, fraction), oldest first
};

}  // namespace filigree
