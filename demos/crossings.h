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
// The edge crossings use a uniform grid that pairs the triangles listed in each of its cells (see
// CrossingCounter, "edge crossings"), the tunnelling a uniform grid over swept triangle boxes
// (testkit::BoxGrid) queried by each vertex's path; between bodies, both hold only the triangles
// whose box reaches another body's. Nothing is quadratic unless the meshes are.
#pragma once

#include "psc/testkit/box_grid.h"
#include "psc/types.h"

#include <Eigen/Core>

#include <array>
#include <cstdint>
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
  /// both directions count (A's edges on B's triangles and B's edges on A's). One grid over the
  /// triangles of all bodies that come near another, each of which tests the edges it owns (every
  /// edge has one owner, fixed by the topology and kept until the body's mesh changes) against the
  /// triangles of other bodies whose boxes meet its own.
  std::size_t edgeCrossings(const std::vector<CrossingMesh>& meshes, const BodyPositions& x);

  /// (edge, triangle) pairs of the same body that share no vertex and with segmentCrossesTriangle,
  /// each once, summed over the bodies. Per body: the pairs whose triangle shares a vertex with
  /// the edge's owner from the topology, the others from a grid over the body's triangles.
  std::size_t selfEdgeCrossings(const std::vector<CrossingMesh>& meshes, const BodyPositions& x);
  /// The same for body b alone.
  std::size_t selfEdgeCrossings(const std::vector<CrossingMesh>& meshes, const BodyPositions& x, std::size_t b);

  /// Vertices v of some body A for which vertexTunnels holds against at least one triangle of a
  /// body B ≠ A between `before` and `after`, leaving out the vertices with skip[A][v] ≠ 0 (skip
  /// may be empty: none left out). With `passed`, it also receives the count of all such vertices,
  /// those with skip[A][v] ≠ 0 included.
  std::size_t tunnelledVertices(const std::vector<CrossingMesh>& meshes, const BodyPositions& before,
                                const BodyPositions& after, const std::vector<std::vector<char>>& skip,
                                std::size_t* passed = nullptr);

 private:
  using Box = testkit::Box;
  /// Fills the grid with the triangles whose box (from `tri_box`) meets the box of another body.
  template <class TriBox>
  void fillGrid(const std::vector<CrossingMesh>& meshes, const std::vector<Box>& body_boxes, TriBox&& tri_box);
  /// Some body other than `body` has a box meeting `b`: items far from every other body need no test.
  static bool meetsOther(const std::vector<Box>& body_boxes, std::size_t body, const Box& b);

  testkit::BoxGrid grid_;  // for the tunnelling; item g: triangle tri_local_[g] of body tri_body_[g]
  std::vector<Index> tri_body_, tri_local_;

  // --- edge crossings: owned edges and the item grid ---
  //
  // Edges are not queried one by one against a grid of triangles (that listed each triangle once
  // per query, deduplicated it by stamps and read its box out of line). Each edge is owned by one
  // triangle instead (or is a lone edge, owned by none), and a grid over the items (the triangles,
  // and the lone edges) pairs the items listed in each cell: two items whose boxes meet test the
  // edges of each against the triangle of the other. A pair of items is met in one cell only (the
  // cell of the upper corner of the two boxes' overlap), so nothing needs deduplicating.
  //  - Within a body, the grid skips two items that share a vertex: the (edge, triangle) pairs
  //    whose triangle shares a vertex with the edge's owner (but none with the edge) are most of
  //    those whose boxes meet on a smooth surface, and the topology lists them (near pairs).
  //  - Between bodies, the items of all bodies that come near another body are in one grid, with
  //    their body for vertices: two items of one body "share a vertex" and are skipped.

  /// What a body's edges need of its mesh, kept while the mesh stays the same.
  struct Topology {
    std::vector<Triangle> triangles;  ///< the mesh it was made from, to notice a new one
    std::vector<Edge> edges;
    /// Per triangle, bit k: it owns its edge from vertex k to vertex k + 1 (mod 3). An edge is
    /// owned by the first triangle listing it, which knows it as (smaller, larger) vertex: the
    /// very order of CrossingMesh::edges, that segmentCrossesTriangle is given.
    std::vector<std::uint8_t> owned;
    std::vector<Index> edge_owner;  ///< per edge: its owner, or kInvalidIndex
    /// The edges no triangle owns: repeated, in no triangle, or not written smaller first.
    std::vector<Edge> lone;
    /// Per owned edge, in the order of the triangles and then of their edges: the triangles that
    /// share a vertex with its owner and none with it (its near pairs).
    IndexRows near;
  };
  /// A box in float, rounded outwards (so that it contains the double one), as two rows of four
  /// lanes for SSE2: lo xyz and hi xyz, the fourth lanes unused.
  struct alignas(16) FloatBox {
    float lo[4], hi[4];
  };
  /// Four items as listed in one cell, field by field, so that one entry is tested against four at
  /// once (lane l of each array is entry l). Each has its box in float and its vertices (or body),
  /// and in bits 0-2 of `ends` the axes along which this cell is the last that the item covers:
  /// two items meet in the cell holding the upper corner of their overlap, the last for one of them
  /// along each axis, so there only is (ends | other.ends) == 7. Lanes past a cell's entries have
  /// an empty box.
  struct alignas(16) CellBlock {
    float lo[3][4], hi[3][4];  ///< [axis][lane]
    Index v[3][4];             ///< [vertex][lane]
    std::uint32_t ends[4];
    Index item[4];
  };
  /// A body's items in the arrays of a call: its triangles are items first_item.., then its lone
  /// edges (lone_[first_lone..]), its vertices' boxes are vertex_boxes_[first_vertex..] and its
  /// triangles' flags left_out_[first_triangle..].
  struct BodyItems {
    const Topology* topo;
    const std::vector<Vec3>* x;
    std::size_t first_item, first_vertex, first_triangle, first_lone, lone_count;
    std::size_t items() const { return topo->triangles.size() + lone_count; }
  };
  /// What the grid needs to know of all items' boxes before it is laid out.
  struct ItemSpan {
    Eigen::Array4f lo, hi;
    double extent_sum = 0.0;
    std::size_t in_grid = 0;
    ItemSpan();
    void add(const FloatBox& box);
  };

  /// The topology of body `b`, rebuilt when its mesh differs from the one it was made from.
  const Topology& topology(std::size_t b, const CrossingMesh& mesh);
  /// Appends a body's items at positions x to the arrays of the call: when some position is not
  /// finite, the triangles touching one are left out (an empty box) and the edges they own become
  /// lone edges if they are finite. Their boxes go into `span` unless it is null (the caller then
  /// decides later which items go into the grid).
  BodyItems addItems(const Topology& topo, const std::vector<Vec3>& x, ItemSpan* span);
  /// Calls pair(i, j) once for every two items whose boxes (boxes_; an empty one is not in the
  /// grid) meet and which share no vertex: no entry of vertices(i) is one of vertices(j).
  template <class Vertices, class Pair>
  void forEachFarPair(const ItemSpan& span, Vertices&& vertices, Pair&& pair);
  /// Calls f(edge) for each edge of item first_item + i of `body`: those its triangle owns, or its
  /// lone edge.
  template <class F>
  void forEachOwnedEdge(const BodyItems& body, std::size_t i, F&& f) const;
  /// The self crossings of one body, the only one in the arrays.
  std::size_t selfCrossingsOf(const BodyItems& body, const ItemSpan& span);

  std::vector<Topology> topology_;  // per body
  // Buffers of a call, kept between calls.
  std::vector<BodyItems> bodies_;
  std::vector<Index> item_body_;           // between bodies: per item, its body in bodies_
  std::vector<std::uint8_t> left_out_;     // per triangle: it has a non-finite vertex
  std::vector<Edge> lone_;                 // the lone edges of the call
  std::vector<FloatBox> vertex_boxes_;     // per vertex: its position rounded outwards
  std::vector<FloatBox> boxes_;            // per item (empty when not in the grid)
  std::vector<std::uint32_t> cell_offsets_;  // per cell: its first lane (a multiple of 4), then the end
  std::vector<std::uint32_t> cell_fill_;     // per cell: its count, then the lane after its entries
  std::vector<CellBlock> cell_blocks_;       // the cells' entries, cell after cell
};

/// References: every edge against every triangle of every other body, and every vertex against
/// every triangle of every other body.
std::size_t edgeCrossingsBruteForce(const std::vector<CrossingMesh>& meshes, const BodyPositions& x);
/// Every edge against every triangle of its own body that shares no vertex with it.
std::size_t selfEdgeCrossingsBruteForce(const std::vector<CrossingMesh>& meshes, const BodyPositions& x);
std::size_t tunnelledVerticesBruteForce(const std::vector<CrossingMesh>& meshes, const BodyPositions& before,
                                        const BodyPositions& after, const std::vector<std::vector<char>>& skip);

}  // namespace psc::demo
