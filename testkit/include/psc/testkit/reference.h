// Exact references shared by the tests, the demos' ground truth and the fuzzers: the point-triangle
// distance and the brute-force (vertex, triangle) contact set. Written independently of the
// library's candidate code on purpose.
#pragma once

#include "psc/mesh.h"
#include "psc/shapes.h"
#include "psc/types.h"
#include "psc/world.h"

#include <cstddef>
#include <utility>
#include <vector>

namespace psc::testkit {

/// Closest point of triangle (a, b, c) to p, exact up to double rounding (Ericson, Real-Time
/// Collision Detection §5.1.5). A degenerate triangle (|ab × ac|² ≤ 1e-24·|ab|²·|ac|²: collinear or
/// point-like) has no reliable face region: its closest point is the nearest of its edges' (a
/// zero-length edge is its vertex), so its distance is still exact.
Vec3 closestPointOnTriangle(const Vec3& p, const Vec3& a, const Vec3& b, const Vec3& c);

/// |p − closestPointOnTriangle(p, a, b, c)|², and the distance itself (its square root, bit for bit).
double pointTriangleDistanceSquared(const Vec3& p, const Vec3& a, const Vec3& b, const Vec3& c);
double pointTriangleDistance(const Vec3& p, const Vec3& a, const Vec3& b, const Vec3& c);

/// The brute-force contact set: calls f(v, t, d) for every point v of `points` and triangle t of
/// `triangles` (indices into `corners`) at exact distance d < radius(v), v ascending, then t. Pairs
/// with skip(v, t) are left out before their distance is computed. No grid, no box test: the
/// reference for small meshes.
template <class Radius, class Skip, class F>
void forEachContact(const std::vector<Vec3>& points, const std::vector<Vec3>& corners,
                    const std::vector<Triangle>& triangles, Radius&& radius, Skip&& skip, F&& f) {
  for (std::size_t v = 0; v < points.size(); ++v) {
    const double r = radius(static_cast<Index>(v));
    for (std::size_t t = 0; t < triangles.size(); ++t) {
      if (skip(static_cast<Index>(v), static_cast<Index>(t))) continue;
      const Triangle& tri = triangles[t];
      const double d = pointTriangleDistance(points[v], corners[tri[0]], corners[tri[1]], corners[tri[2]]);
      if (d < r) f(static_cast<Index>(v), static_cast<Index>(t), d);
    }
  }
}

/// The same over every pair.
template <class Radius, class F>
void forEachContact(const std::vector<Vec3>& points, const std::vector<Vec3>& corners,
                    const std::vector<Triangle>& triangles, Radius&& radius, F&& f) {
  forEachContact(points, corners, triangles, radius, [](Index, Index) { return false; }, f);
}

/// The self-collision exclusion rule (psc::SensorWorld::setSelfCollision), written apart from the
/// core: vertex v and triangle t of one body are never a self contact when t holds v, or when v was
/// closer to t than rest_exclusion × self_radius (the body's self contact radius) in the body's
/// rest shape `rest` (what touches at rest is the surface itself, not a fold).
bool selfPairExcluded(Index v, const Triangle& t, const std::vector<Vec3>& rest, double self_radius,
                      double rest_exclusion);

/// The thesis's candidate sets of one flagged region pair in one direction (§3.5), from the
/// definition alone: the vertices of region `vertex_region` of the vertex body (with `one_ring`,
/// also their neighbours in other regions) and the triangles of the other body with a corner in
/// `triangle_region` (with `one_ring`, also the triangles at that region's ring vertices). Both
/// sorted. The core's thesis mode tests exactly these sets.
struct RegionSets {
  std::vector<Index> vertices;
  std::vector<Index> triangles;
};
RegionSets regionSets(const MeshTopology& vertex_topology, const std::vector<Index>& vertex_region_of,
                      Index vertex_region, const MeshTopology& triangle_topology,
                      const std::vector<Index>& triangle_region_of, Index triangle_region, bool one_ring);
/// The same for a flagged pair of `world` (after its step), vertices of `vertex_body` (one of the
/// pair's bodies) against triangles of the other, with the world's one_ring setting.
RegionSets regionSets(const SensorWorld& world, const FlaggedPair& pair, BodyId vertex_body);

/// (vertex of `vm`, triangle of `tm`) pairs closer than `radius`, in that order.
std::vector<std::pair<Index, Index>> bruteContacts(const TriMesh& vm, const TriMesh& tm, double radius);

}  // namespace psc::testkit
