#include "support/test_meshes.h"

#include <cmath>
#include <fstream>
#include <sstream>
#include <map>
#include <numbers>

#include "mesh/mesh_io.h"

namespace filigree::test {

TriMesh icosphere(int levels) {
  const double t = (1.0 + std::sqrt(5.0)) / 2.0;
  TriMesh m;
  m.positions = {{-1, t, 0}, {1, t, 0}, {-1, -t, 0}, {1, -t, 0}, {0, -1, t}, {0, 1, t},
                 {0, -1, -t}, {0, 1, -t}, {t, 0, -1}, {t, 0, 1}, {-t, 0, -1}, {-t, 0, 1}};
  m.faces = {{0, 11, 5}, {0, 5, 1},  {0, 1, 7},   {0, 7, 10}, {0, 10, 11}, {1, 5, 9}, {5, 11, 4},
             {11, 10, 2}, {10, 7, 6}, {7, 1, 8},  {3, 9, 4},  {3, 4, 2},   {3, 2, 6}, {3, 6, 8},
             {3, 8, 9},  {4, 9, 5},  {2, 4, 11},  {6, 2, 10}, {8, 6, 7},   {9, 8, 1}};
  for (Vec3& p : m.positions) p.normalize();
  for (int l = 0; l < levels; ++l) {
    std::map<std::pair<Index, Index>, Index> mid;
    auto midpoint = [&](Index a, Index b) {
      const auto key = std::minmax(a, b);
      const auto it = mid.find(key);
      if (it != mid.end()) return it->second;
      const Index i = static_cast<Index>(m.positions.size());
      m.positions.push_back((m.positions[a] + m.positions[b]).normalized());
      mid.emplace(key, i);
      return i;
    };
    std::vector<Triangle> faces;
    for (const Triangle& f : m.faces) {
      const Index a = midpoint(f[0], f[1]), b = midpoint(f[1], f[2]), c = midpoint(f[2], f[0]);
      faces.insert(faces.end(), {{f[0], a, c}, {f[1], b, a}, {f[2], c, b}, {a, b, c}});
    }
    m.faces = std::move(faces);
  }
  return m;
}

TriMesh torus(int rings, int sides, double major, double minor) {
  TriMesh m;
  for (int i = 0; i < rings; ++i) {
    const double u = 2.0 * std::numbers::pi * i / rings;
    for (int j = 0; j < sides; ++j) {
      const double v = 2.0 * std::numbers::pi * j / sides;
      m.positions.emplace_back((major + minor * std::cos(v)) * std::cos(u), (major + minor * std::cos(v)) * std::sin(u),
                               minor * std::sin(v));
    }
  }
  auto id = [&](int i, int j) { return static_cast<Index>((i % rings) * sides + (j % sides)); };
  for (int i = 0; i < rings; ++i)
    for (int j = 0; j < sides; ++j) {
      m.faces.push_back({id(i, j), id(i + 1, j), id(i + 1, j + 1)});
      m.faces.push_back({id(i, j), id(i + 1, j + 1), id(i, j + 1)});
    }
  return m;
}

TriMesh capped_tube(int rings, int sides, double length, double radius) {
  TriMesh m;
  for (int i = 0; i < rings; ++i) {
    const double x = length * i / (rings - 1);
    for (int j = 0; j < sides; ++j) {
      const double a = 2.0 * std::numbers::pi * j / sides;
      m.positions.emplace_back(x, radius * std::cos(a), radius * std::sin(a));
    }
  }
  auto id = [&](int i, int j) { return static_cast<Index>(i * sides + (j % sides)); };
  for (int i = 0; i + 1 < rings; ++i)
    for (int j = 0; j < sides; ++j) {
      m.faces.push_back({id(i, j), id(i + 1, j), id(i + 1, j + 1)});
      m.faces.push_back({id(i, j), id(i + 1, j + 1), id(i, j + 1)});
    }
  const auto start = static_cast<Index>(m.positions.size());
  m.positions.emplace_back(-0.5 * radius, 0.0, 0.0);
  m.positions.emplace_back(length + 0.5 * radius, 0.0, 0.0);
  for (int j = 0; j < sides; ++j) {
    // Each cap edge runs opposite to the wall face's use of it (consistent orientation).
    m.faces.push_back({start, id(0, j), id(0, j + 1)});
    m.faces.push_back({static_cast<Index>(start + 1), id(rings - 1, j + 1), id(rings - 1, j)});
  }
  return m;
}

TriMesh wavy_grid(int n) {
  TriMesh m;
  for (int i = 0; i <= n; ++i)
    for (int j = 0; j <= n; ++j) {
      const double x = static_cast<double>(i) / n, y = static_cast<double>(j) / n;
      m.positions.emplace_back(x, y, 0.08 * std::sin(6.0 * x) * std::cos(5.0 * y));
    }
  auto id = [&](int i, int j) { return static_cast<Index>(i * (n + 1) + j); };
  for (int i = 0; i < n; ++i)
    for (int j = 0; j < n; ++j) {
      m.faces.push_back({id(i, j), id(i + 1, j), id(i + 1, j + 1)});
      m.faces.push_back({id(i, j), id(i + 1, j + 1), id(i, j + 1)});
    }
  return m;
}

TriMesh two_spheres(int levels) {
  TriMesh a = icosphere(levels);
  const TriMesh b = icosphere(levels);
  const Index offset = static_cast<Index>(a.positions.size());
  for (const Vec3& p : b.positions) a.positions.push_back(p + Vec3(3.0, 0.5, 0.0));
  for (const Triangle& f : b.faces) a.faces.push_back({f[0] + offset, f[1] + offset, f[2] + offset});
  return a;
}

std::string shipped_path(const std::string& file_name) { return std::string(FILIGREE_TEST_DATA_DIR) + "/" + file_name; }

std::string file_bytes(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::ostringstream s;
  s << in.rdbuf();
  return s.str();
}

TriMesh shipped_mesh(const std::string& file_name) { return read_mesh(shipped_path(file_name)); }

}  // namespace filigree::test
