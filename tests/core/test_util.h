// Small header-only helpers shared by the core tests. Append only; keep each helper independent of
// the library code it may be used to check.
#pragma once

#include "psc/types.h"

#include <Eigen/Geometry>  // cross()

#include <algorithm>
#include <map>
#include <numeric>
#include <utility>
#include <vector>

namespace psc::test {

/// Edge facts of a triangle soup, computed by brute force (a reference, not the library's
/// MeshTopology): how many triangles use each undirected edge, and how many directed edges repeat.
struct EdgeCensus {
  std::size_t edges = 0;
  std::size_t boundary = 0;            ///< used by exactly one triangle
  std::size_t manifold = 0;            ///< used by exactly two triangles
  std::size_t non_manifold = 0;        ///< used by more than two
  std::size_t same_direction = 0;      ///< interior edges traversed the same way twice (bad winding)
  std::size_t degenerate_triangles = 0;  ///< a repeated vertex index
};

inline EdgeCensus edgeCensus(const std::vector<Triangle>& triangles) {
  std::map<std::pair<Index, Index>, std::pair<int, int>> uses;  // (a<b) -> (a→b count, b→a count)
  EdgeCensus c;
  for (const Triangle& t : triangles) {
    if (t[0] == t[1] || t[1] == t[2] || t[2] == t[0]) ++c.degenerate_triangles;
    for (int k = 0; k < 3; ++k) {
      const Index a = t[k], b = t[(k + 1) % 3];
      auto& u = uses[std::minmax(a, b)];
      (a < b ? u.first : u.second) += 1;
    }
  }
  c.edges = uses.size();
  for (const auto& [edge, u] : uses) {
    const int total = u.first + u.second;
    if (total == 1) ++c.boundary;
    else if (total == 2) ++c.manifold;
    else ++c.non_manifold;
    if (total == 2 && u.first != 1) ++c.same_direction;
  }
  return c;
}

/// Volume enclosed by a closed, consistently wound surface: positive when wound outward.
inline double signedVolume(const std::vector<Vec3>& v, const std::vector<Triangle>& triangles) {
  double six = 0.0;
  for (const Triangle& t : triangles) six += v[t[0]].dot(v[t[1]].cross(v[t[2]]));
  return six / 6.0;
}

/// Connected components over shared triangle vertices (vertices in no triangle are not counted).
inline std::size_t triangleComponents(std::size_t vertex_count, const std::vector<Triangle>& triangles) {
  std::vector<Index> parent(vertex_count);
  std::iota(parent.begin(), parent.end(), Index{0});
  auto find = [&](Index x) {
    while (parent[x] != x) x = parent[x] = parent[parent[x]];
    return x;
  };
  std::vector<bool> used(vertex_count, false);
  for (const Triangle& t : triangles) {
    for (int k = 0; k < 3; ++k) used[t[k]] = true;
    parent[find(t[0])] = find(t[1]);
    parent[find(t[1])] = find(t[2]);
  }
  std::size_t count = 0;
  for (Index i = 0; i < vertex_count; ++i) count += (used[i] && find(i) == i) ? 1 : 0;
  return count;
}

/// Smallest triangle area relative to the mean (a quick sliver/degeneracy detector).
inline double minAreaRatio(const std::vector<Vec3>& v, const std::vector<Triangle>& triangles) {
  double lo = 1e300, sum = 0.0;
  for (const Triangle& t : triangles) {
    const double a = 0.5 * (v[t[1]] - v[t[0]]).cross(v[t[2]] - v[t[0]]).norm();
    lo = std::min(lo, a);
    sum += a;
  }
  return triangles.empty() ? 0.0 : lo / (sum / double(triangles.size()));
}

}  // namespace psc::test

// --- OFF reader and region connectivity reference (partition tests) -----------------------------
#include <fstream>
#include <sstream>
#include <stdexcept>
#include <string>

namespace psc::test {

/// Vertices and triangles read from an ASCII OFF file ("OFF", then "V F E", V lines "x y z", F lines
/// "n i0 .. i{n-1}"); polygons are fanned into triangles. Comments (#) and blank lines are skipped.
/// Throws std::runtime_error naming the file on anything else.
struct OffMesh {
  std::vector<Vec3> vertices;
  std::vector<Triangle> triangles;
};

inline OffMesh readOff(const std::string& path) {
  std::ifstream in(path);
  if (!in) throw std::runtime_error("cannot open " + path);
  std::stringstream body;
  for (std::string line; std::getline(in, line);) {
    const std::size_t hash = line.find('#');
    if (hash != std::string::npos) line.erase(hash);
    body << line << '\n';
  }
  std::string magic;
  std::size_t nv = 0, nf = 0, ne = 0;
  if (!(body >> magic) || magic != "OFF" || !(body >> nv >> nf >> ne))
    throw std::runtime_error(path + ": not an ASCII OFF file");
  OffMesh m;
  m.vertices.resize(nv);
  for (Vec3& v : m.vertices)
    if (!(body >> v.x() >> v.y() >> v.z())) throw std::runtime_error(path + ": truncated vertex list");
  for (std::size_t f = 0; f < nf; ++f) {
    std::size_t n = 0;
    if (!(body >> n) || n < 3) throw std::runtime_error(path + ": bad face " + std::to_string(f));
    std::vector<Index> poly(n);
    for (Index& i : poly)
      if (!(body >> i) || i >= nv) throw std::runtime_error(path + ": bad index in face " + std::to_string(f));
    for (std::size_t k = 1; k + 1 < n; ++k) m.triangles.push_back({poly[0], poly[k], poly[k + 1]});
  }
  return m;
}

/// Pieces of each region: connected parts of the subgraph of triangle edges whose two ends share a
/// region (vertices in no triangle are ignored). A brute-force reference with its own union-find.
inline std::vector<std::size_t> regionPieces(std::size_t vertex_count, const std::vector<Triangle>& triangles,
                                             const std::vector<Index>& region_of, std::size_t region_count) {
  std::vector<Index> parent(vertex_count);
  std::iota(parent.begin(), parent.end(), Index{0});
  auto find = [&](Index x) {
    while (parent[x] != x) x = parent[x] = parent[parent[x]];
    return x;
  };
  std::vector<bool> used(vertex_count, false);
  for (const Triangle& t : triangles) {
    for (int k = 0; k < 3; ++k) {
      used[t[k]] = true;
      const Index a = t[k], b = t[(k + 1) % 3];
      if (region_of[a] == region_of[b]) parent[find(a)] = find(b);
    }
  }
  std::vector<std::size_t> pieces(region_count, 0);
  for (Index i = 0; i < vertex_count; ++i)
    if (used[i] && find(i) == i) ++pieces[region_of[i]];
  return pieces;
}

}  // namespace psc::test

namespace psc::test {

/// Pairs of triangles that share no vertex yet cross (an edge of one passes through the other),
/// brute force over all pairs with a box prefilter: a reference for small meshes only.
inline std::size_t selfIntersections(const std::vector<Vec3>& v, const std::vector<Triangle>& triangles) {
  auto segmentHits = [&](const Vec3& p, const Vec3& q, const Triangle& t) {
    const Vec3 &a = v[t[0]], &b = v[t[1]], &c = v[t[2]];
    const Vec3 n = (b - a).cross(c - a);
    const double dp = n.dot(p - a), dq = n.dot(q - a);
    if ((dp > 0 && dq > 0) || (dp < 0 && dq < 0) || dp == dq) return false;
    const Vec3 x = p + (dp / (dp - dq)) * (q - p);
    const double s0 = n.dot((b - a).cross(x - a)), s1 = n.dot((c - b).cross(x - b)), s2 = n.dot((a - c).cross(x - c));
    return (s0 > 0 && s1 > 0 && s2 > 0) || (s0 < 0 && s1 < 0 && s2 < 0);
  };
  std::vector<Vec3> lo(triangles.size()), hi(triangles.size());
  for (std::size_t i = 0; i < triangles.size(); ++i) {
    lo[i] = v[triangles[i][0]].cwiseMin(v[triangles[i][1]]).cwiseMin(v[triangles[i][2]]);
    hi[i] = v[triangles[i][0]].cwiseMax(v[triangles[i][1]]).cwiseMax(v[triangles[i][2]]);
  }
  std::size_t hits = 0;
  for (std::size_t i = 0; i < triangles.size(); ++i) {
    for (std::size_t j = i + 1; j < triangles.size(); ++j) {
      if ((lo[i].array() > hi[j].array()).any() || (lo[j].array() > hi[i].array()).any()) continue;
      const Triangle &s = triangles[i], &t = triangles[j];
      bool shared = false;
      for (Index a : s) for (Index b : t) shared = shared || a == b;
      if (shared) continue;
      bool cross = false;
      for (int k = 0; k < 3 && !cross; ++k) {
        cross = segmentHits(v[s[k]], v[s[(k + 1) % 3]], t) || segmentHits(v[t[k]], v[t[(k + 1) % 3]], s);
      }
      hits += cross ? 1 : 0;
    }
  }
  return hits;
}

}  // namespace psc::test

#include "psc/error.h"

#include <functional>
#include <string>

namespace psc::test {

/// The message of the psc::Error that `f` throws, or "no error".
inline std::string messageOf(const std::function<void()>& f) {
  try {
    f();
  } catch (const Error& e) {
    return e.what();
  }
  return "no error";
}

}  // namespace psc::test

#include "psc/shapes.h"

#include <array>

namespace psc::test {

/// Thesis chapter 4, case 4: two U shapes (arm axes 1 apart, arms 1 long, tube radius 0.2, about
/// 1200 vertices each) hooked like two chain links. a lies in the xy plane, its bend's centreline
/// lowest at (0, -0.5, 0); b is turned into the yz plane and upside down (bend on top, arms at
/// z = ±0.5 pointing down), so b's bend hooks through a's opening and a's bend passes under it.
/// The tubes cross at x = z = 0 with b's inner surface `gap` above a's outer one.
inline std::array<TriMesh, 2> interlockedUShapes(double gap) {
  constexpr double kHalfTurn = 3.14159265358979323846;
  TriMesh a = makeUShape(1.0, 1.0, 0.2, 1200);
  TriMesh b = makeUShape(1.0, 1.0, 0.2, 1200);
  b.rotate(Vec3(0, 1, 0), kHalfTurn / 2).rotate(Vec3(0, 0, 1), kHalfTurn).translate(Vec3(0.0, -0.6 + gap, 0.0));
  return {a, b};
}

}  // namespace psc::test
