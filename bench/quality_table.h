#pragma once
// `filigree_bench_runtime --table`: one table to choose T by. Real meshes ×
// motions (twist, bend, bump, fold, twist360) × settings (T = 0, 2e4, 2e5,
// ∞, and ∞ with 10 local–global iterations); each cell the RMS and max
// distance to the truth (% of the bbox diagonal), the mean normal deviation
// (degrees) and the median time per frame (ms). Then the runtime's quality
// targets, each computed from the table, and each setting's error and time
// relative to T = 0.

#include <string>
#include <vector>

namespace filigree::bench {

struct TableMesh {
  std::string name;  // as the table prints it
  std::string kind;  // what kind of mesh it is (thin limbs, a scan, genus 3…)
  std::string path;  // a missing file is skipped with a note
};

void print_quality_table(const std::vector<TableMesh>& meshes, int threads);

}  // namespace filigree::bench
