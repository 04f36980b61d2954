// Brute-force references for the world tests: exact point-triangle distance and the contacts
// between two meshes. Written independently of the library's candidate code on purpose.
#pragma once

#include "psc/shapes.h"
#include "psc/types.h"

#include <Eigen/Geometry>

#include <algorithm>
#include <cstdint>
#include <set>
#include <tuple>
#include <vector>

namespace psc::test {

/// Closest point on triangle abc to p (Ericson, Real-Time Collision Detection §5.1.5).
inline Vec3 closestPointOnTriangle(const Vec3& p, const Vec3& a, const Vec3& b, const Vec3& c) {
  const Vec3 ab = b - a, ac = c - a, ap = p - a;
  const double d1 = ab.dot(ap), d2 = ac.dot(ap);
  if (d1 <= 0 && d2 <= 0) return a;
  const Vec3 bp = p - b;
  const double d3 = ab.dot(bp), d4 = ac.dot(bp);
  if (d3 >= 0 && d4 <= d3) return b;
  const double vc = d1 * d4 - d3 * d2;
  if (vc <= 0 && d1 >= 0 && d3 <= 0) return a + ab * (d1 / (d1 - d3));
  const Vec3 cp = p - c;
  const double d5 = ab.dot(cp), d6 = ac.dot(cp);
  if (d6 >= 0 && d5 <= d6) return c;
  const double vb = d5 * d2 - d1 * d6;
  if (vb <= 0 && d2 >= 0 && d6 <= 0) return a + ac * (d2 / (d2 - d6));
  const double va = d3 * d6 - d5 * d4;
  if (va <= 0 && (d4 - d3) >= 0 && (d5 - d6) >= 0) return b + (c - b) * ((d4 - d3) / ((d4 - d3) + (d5 - d6)));
  const double denom = 1.0 / (va + vb + vc);
  return a + ab * (vb * denom) + ac * (vc * denom);
}

inline double pointTriangleDistance(const Vec3& p, const Vec3& a, const Vec3& b, const Vec3& c) {
  return (p - closestPointOnTriangle(p, a, b, c)).norm();
}

/// (vertex of `vm`, triangle of `tm`) pairs closer than `radius`, by brute force.
inline std::vector<std::pair<Index, Index>> bruteContacts(const TriMesh& vm, const TriMesh& tm, double radius) {
  std::vector<std::pair<Index, Index>> out;
  for (Index v = 0; v < vm.vertices.size(); ++v)
    for (Index t = 0; t < tm.triangles.size(); ++t) {
      const Triangle& tri = tm.triangles[t];
      if (pointTriangleDistance(vm.vertices[v], tm.vertices[tri[0]], tm.vertices[tri[1]], tm.vertices[tri[2]]) <
          radius)
        out.emplace_back(v, t);
    }
  return out;
}

}  // namespace psc::test
