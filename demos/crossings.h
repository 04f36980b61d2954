// Two failure counts of a step (docs/BENCHMARK.md, "Crossings and tunnelling"), computed from plain
// arrays so that they need no Bullet and can be tested against brute force:
//  - edge–triangle crossings: an undirected mesh edge of body A whose segment properly intersects a
//    triangle of body B ≠ A, on the positions after the step. Two surfaces that pass into each
//    other cross along the curve where they meet, whether or not they are closed.
//  - self crossings: the same within one body, between an edge and a triangle that share no vertex
//    (an edge always touches the triangles around it): a surface passing through itself.
//  - tunnelled vertices: a vertex of A whose path over the step (a segment from its position before
//    the step to after it) passes through a triangle of B ≠ A moving linearly from its own before
//    to after positions (a continuous vertex–triangle test).
// Both use a uniform grid over triangle boxes (testkit::BoxGrid; swept boxes for the tunnelling),
// filled only with the triangles whose box reaches another body's box: nothing is quadratic unless
// the meshes are.
#pragma once

#include "psc/testkit/box_grid.h"
#include "psc/types.h"

#include <array>
#include <vector>

namespace psc::demo {

using Edge = std::array<Index, 2>;  ///< two vertex indices, smaller first

/// The undirected edges of a triangle mesh, each once, sorted.
std::vector<Edge> meshEdges(const std::vector<Triangle>& triangles);

/// A body's fixed topology: its triangles and their edges.
struct CrossingMesh {
  std::vector<Triangle> triangles;
  std::vector<Edge> edges;  ///< meshEdges(triangles)
};
CrossingMesh crossingMesh(std::vector<Triangle> triangles);

/// Positions of every body's vertices, one vector per body (body b indexes meshes[b]).
using BodyPositions = std::vector<std::vector<Vec3>>;

/// Segment pq properly intersects triangle abc: p and q strictly on opposite sides of its plane and
/// the crossing point strictly inside its three edges (signs of orientation determinants in double).
/// Touching, coplanar and degenerate inputs (zero-length segment, zero-area triangle) are not
/// crossings.
bool segmentCrossesTriangle(const Vec3& p, const Vec3& q, const Vec3& a, const Vec3& b, const Vec3& c);

/// Barycentric slack of the inside test of vertexTunnels: a crossing point within 1e-7 of the
/// triangle's size outside an edge still counts, so that a path through a shared edge is not lost
/// between the two triangles.
inline constexpr double kTunnelInsideTolerance = 1e-7;

/// A point moving linearly from p0 to p1 passes through triangle (a, b, c) moving linearly from
/// (a0, b0, c0) to (a1, b1, c1) over the same interval: the signed volume of (p, a, b, c), a cubic
/// in time, changes sign strictly in [0, 1], and at that root the point lies inside the triangle
/// (kTunnelInsideTolerance). Touching the plane and turning back, or starting or ending on it, is no
/// crossing. Every sign change is tried, so a path through the triangle and back counts.
bool vertexTunnels(const Vec3& p0, const Vec3& p1, const Vec3& a0, const Vec3& b0, const Vec3& c0, const Vec3& a1,
                   const Vec3& b1, const Vec3& c1);

/// Keeps the grid's buffers between steps. Non-finite positions are never counted.
class CrossingCounter {
 public:
  /// (edge of body A, triangle of body B) pairs with A ≠ B and segmentCrossesTriangle, each once;
  /// both directions count (A's edges on B's triangles and B's edges on A's).
  std::size_t edgeCrossings(const std::vector<CrossingMesh>& meshes, const BodyPositions& x);

  /// (edge, triangle) pairs of the same body that share no vertex and with segmentCrossesTriangle,
  /// each once, summed over the bodies. One grid per body over its own triangles.
  std::size_t selfEdgeCrossings(const std::vector<CrossingMesh>& meshes, const BodyPositions& x);

  /// Vertices v of some body A for which vertexTunnels holds against at least one triangle of a
  /// body B ≠ A between `before` and `after`, leaving out the vertices with skip[A][v] ≠ 0 (skip
  /// may be empty: none left out).
  std::size_t tunnelledVertices(const std::vector<CrossingMesh>& meshes, const BodyPositions& before,
                                const BodyPositions& after, const std::vector<std::vector<char>>& skip);

 private:
  using Box = testkit::Box;
  /// Fills the grid with the triangles whose box (from `tri_box`) meets the box of another body.
  template <class TriBox>
  void fillGrid(const std::vector<CrossingMesh>& meshes, const std::vector<Box>& body_boxes, TriBox&& tri_box);
  /// Some body other than `body` has a box meeting `b`: items far from every other body need no test.
  static bool meetsOther(const std::vector<Box>& body_boxes, std::size_t body, const Box& b);

  testkit::BoxGrid grid_;  // item g: triangle tri_local_[g] of body tri_body_[g]
  std::vector<Index> tri_body_, tri_local_;
};

/// References: every edge against every triangle of every other body, and every vertex against
/// every triangle of every other body.
std::size_t edgeCrossingsBruteForce(const std::vector<CrossingMesh>& meshes, const BodyPositions& x);
/// Every edge against every triangle of its own body that shares no vertex with it.
std::size_t selfEdgeCrossingsBruteForce(const std::vector<CrossingMesh>& meshes, const BodyPositions& x);
std::size_t tunnelledVerticesBruteForce(const std::vector<CrossingMesh>& meshes, const BodyPositions& before,
                                        const BodyPositions& after, const std::vector<std::vector<char>>& skip);

}  // namespace psc::demo
