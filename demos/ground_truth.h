// The contacts that exist (docs/BENCHMARK.md, "Ground truth"), computed independently of both
// pipelines: a dense uniform grid over the triangles of all bodies and the exact point-triangle
// distance in double, both from psc::testkit. Shares no candidate-finding code with psc::core or
// the plugin; a test checks it against the brute-force reference below on small scenes, both radii.
//
// For bodies A ≠ B, vertex v of A and triangle t of B are in contact when dist(v, t) < r with
//   strict: r = margin_A + margin_B
//   full:   r = margin_A + margin_B + 2·|x_v − x_v,prev|   (exactly Bullet's CollideVF_SS radius)
// Bullet decides in single precision; a pair within a thin band around r (tolerance below) could go
// either way on rounding alone, so it is classed Ambiguous: neither required for recall nor counted
// as "outside the truth".
//
// Self-collision (computeSelf): vertex v and triangle t of the same body, with the body's self
// contact radius R (psc::selfContactRadius: max(2·margin, radius_edges × mean rest edge)) in
// place of margin_A + margin_B, leaving out the pairs the exclusion rule names
// (testkit::selfPairExcluded: t holds v, or the two were within rest_exclusion × R in the body's
// rest shape).
#pragma once

#include "psc/testkit/box_grid.h"
#include "psc/types.h"

#include <array>
#include <cstdint>
#include <vector>

namespace psc::demo {

/// One body as the truth sees it. Positions at the moment contacts are decided (in Bullet: m_x
/// after predictMotion) and one step earlier (m_q).
struct TruthBody;

/// The self-collision rule of every body (psc::SensorWorld::setSelfCollision, restated).
struct SelfRule {
  std::vector<std::vector<Vec3>> rest;  ///< each body's rest shape (its vertex count)
  std::vector<double> rest_mean_edge;   ///< mean edge length of each rest shape
  double rest_exclusion = 2.0;          ///< psc::SensorSettings::self_rest_exclusion
  double radius_edges = 1.0;            ///< psc::SensorSettings::self_radius_edges
  /// Body b's self contact radius (margin from `body`, as the plugin reads it each step).
  double radius(const TruthBody& body, std::size_t b) const;
};

/// The body's mean displacement (x − prev) over its vertices that are in triangles: the `mean` of
/// its self motion term (psc::selfMotion).
Vec3 meanDisplacement(const TruthBody& body);

/// The rule for bodies with these triangles and rest shapes, with the core's default factors.
SelfRule selfRule(const std::vector<std::vector<Triangle>>& triangles, std::vector<std::vector<Vec3>> rest);

struct TruthBody {
  std::vector<Vec3> x;
  std::vector<Vec3> prev;           ///< same size as x; may equal x (no motion term)
  std::vector<Triangle> triangles;
  double margin = 0.0;              ///< length units
  bool closed = false;              ///< closed surface: vertices of others can be inside it
};

/// A vertex of one body against a triangle of another. Ordered by all four fields.
struct ContactKey {
  Index vertex_body = 0;
  Index vertex = 0;
  Index triangle_body = 0;
  Index triangle = 0;
  bool operator==(const ContactKey& o) const {
    return vertex_body == o.vertex_body && vertex == o.vertex && triangle_body == o.triangle_body && triangle == o.triangle;
  }
  bool operator<(const ContactKey& o) const {
    if (vertex_body != o.vertex_body) return vertex_body < o.vertex_body;
    if (triangle_body != o.triangle_body) return triangle_body < o.triangle_body;
    if (vertex != o.vertex) return vertex < o.vertex;
    return triangle < o.triangle;
  }
};

enum class Membership : std::uint8_t { Outside, Ambiguous, Inside };

struct TruthContact {
  ContactKey key;
  Membership strict = Membership::Outside;
  Membership full = Membership::Outside;  ///< Outside when the full radius was not asked for
  double distance = 0.0;
};

struct TruthSettings {
  bool strict = true;
  bool full = true;
  /// Half-width of the Ambiguous band: band_relative·r + band_absolute (length units). The caller
  /// sets band_absolute from the precision of the positions it was given (float: ~1e-6 × scene size).
  double band_relative = 1e-5;
  double band_absolute = 0.0;
};

struct TruthResult {
  std::vector<TruthContact> contacts;  ///< sorted by key; every pair not Outside for some asked radius
  std::size_t strict_inside = 0, strict_ambiguous = 0;
  std::size_t full_inside = 0, full_ambiguous = 0;
  std::size_t distance_tests = 0;      ///< exact distances computed (a cost figure)
  const TruthContact* find(const ContactKey& key) const;  ///< binary search; nullptr if absent
};

struct Penetration;
class TriangleGrid;
Penetration measurePenetration(const std::vector<TruthBody>& bodies, TriangleGrid& grid);

/// The inside test of measurePenetration for one body and one ray axis: the parity of the
/// crossings of the ray from p along +axis with the body's triangles, exactly as
/// TriangleGrid::rayParityOdd counts them (same triangles, same tie rule), for many points p.
/// The triangles are binned in a 2D grid across the axis (coordinates u = axis+1, w = axis+2
/// mod 3), so a ray looks at the few triangles of its own column of this body instead of walking
/// the cells of every body's triangles to the end of a 3D grid. A triangle goes into the cell of
/// the low corner of its box and then every other cell of its box's range, and a query reads the
/// 2×2 cells ending at its own: exactly one of them holds each triangle whose box spans the point.
class RayColumns {
 public:
  /// Over `body`'s triangles at positions body.x (copied: the body may go). Triangles whose box
  /// has a NaN coordinate are left out, as TriangleGrid's cells leave them out.
  void build(const TruthBody& body, int axis);
  /// Parity of the crossings of the ray from p along +axis. Even (false) for a p with a NaN.
  bool parityOdd(const Vec3& p) const;

  /// The grid, for tests: cell (i, j) spans about origin + [i, i+1)·cellSize along u, and
  /// likewise along w (a point on a boundary may fall either way), i < dims()[0], j < dims()[1].
  int axis() const { return axis_; }
  double originU() const { return origin_u_; }
  double originW() const { return origin_w_; }
  double cellSize() const { return cell_; }
  std::array<std::int64_t, 2> dims() const { return {nu_, nw_}; }

 private:
  // What a ray reads of a triangle: in each of its cells, its box rounded outward to float (a
  // test on a few bytes that passes all the triangles the exact one passes) and where its
  // corners are, (u, w, axis) each, in one place rather than in three vertices of the body.
  struct Item {
    float lo_u, hi_u, lo_w, hi_w, hi_a;
    std::uint32_t corners;  // index into corners_
  };
  struct Corners {
    double c[9];  // corner k: c[3k], c[3k+1], c[3k+2] = its u, w and axis coordinates
  };
  // A triangle in the build: its box across the axis.
  struct Pending {
    double lo_u, hi_u, lo_w, hi_w;
    Index triangle;
  };
  static constexpr double kCellPerBox = 0.75;  // cell width / mean width of a triangle's box
  std::int64_t cellU(double x) const;
  std::int64_t cellW(double x) const;

  int axis_ = 0;
  double origin_u_ = 0.0, origin_w_ = 0.0, cell_ = 1.0, inv_cell_ = 1.0;
  std::int64_t nu_ = 0, nw_ = 0;        // 0: nothing to cross
  std::vector<std::uint32_t> offsets_;  // CSR over cells, u fastest
  std::vector<Item> items_;             // in the cells' order; grown only (no refill when reused)
  std::vector<Corners> corners_;        // per triangle in pending_ order; grown only
  std::vector<Pending> pending_;
  std::vector<std::uint32_t> fill_;
};

/// Uniform grid over all triangles of all bodies (a testkit::BoxGrid over their boxes), rebuilt
/// from scratch for each query set.
class TriangleGrid {
 public:
  /// cell ≤ 0: chosen from the mean edge length; the cell count is capped near 2× the triangles.
  void build(const std::vector<TruthBody>& bodies, double cell = 0.0);

  /// Calls f(body, triangle) once for every triangle whose bounding box meets [lo, hi].
  template <class F>
  void forEachInBox(const Vec3& lo, const Vec3& hi, F&& f) const {
    grid_.forEachInBox(lo, hi, [&](Index g) { f(tri_body_[g], tri_local_[g]); });
  }

  /// Parity of the crossings of the ray from p along +axis (0, 1, 2) with `body`'s triangles.
  /// Edges and vertices hit exactly are counted once by a consistent tie rule.
  bool rayParityOdd(const Vec3& p, Index body, int axis) const;

  /// Distance from p to the nearest triangle of `body`, searching outward from `start` (> 0).
  double nearestDistance(const Vec3& p, Index body, double start) const;

 private:
  friend class GroundTruth;
  friend Penetration measurePenetration(const std::vector<TruthBody>& bodies, TriangleGrid& grid);

  const std::vector<TruthBody>* bodies_ = nullptr;
  testkit::BoxGrid grid_;                // item g: triangle tri_local_[g] of body tri_body_[g]
  std::vector<Index> tri_body_, tri_local_;
  std::vector<Vec3> body_lo_, body_hi_;  // bounds of each body's triangles

  // measurePenetration's own structures, one per body, kept between calls and built only for a
  // body that some vertex of another body lies inside the box of (grid_ is not built for it).
  struct PenetrationBody {
    Vec3 vertex_lo, vertex_hi;      // box of its vertices, NaN coordinates left out
    bool vertex_nan = false;        // some vertex has a NaN coordinate
    Vec3 lo, hi;                    // box of its triangles' boxes, computed as build() does
    bool box_built = false;
    RayColumns columns[2];          // rays along +x and +y
    bool columns_built[2] = {false, false};
    testkit::BoxGrid distance;      // its triangles' boxes (item = triangle), for the depths
    Vec3 visible_lo, visible_hi;    // bounds of the boxes without NaN, the ones `distance` holds
    bool distance_built = false;
    bool any_visible = false;
    /// Whether depth = nearestDistance(p, this body, strict) is > strict, then with that depth;
    /// over `distance` (built on first use).
    bool deeperThan(const TruthBody& body, const Vec3& p, double strict, double& depth);
  };
  std::vector<PenetrationBody> pen_;
};

/// Computes the truth with the grid; keeps its buffers between calls.
class GroundTruth {
 public:
  const TruthResult& compute(const std::vector<TruthBody>& bodies, const TruthSettings& settings);
  /// Every body's contacts with itself (keys with vertex_body == triangle_body): strict radius
  /// R = rule.radius(b), full R + 2·psc::selfMotion(x_v − x_v,prev, meanDisplacement(body)),
  /// without the pairs testkit::selfPairExcluded
  /// names for the rule. Its own result: compute()'s stays valid.
  const TruthResult& computeSelf(const std::vector<TruthBody>& bodies, const SelfRule& rule,
                                 const TruthSettings& settings);
  const TriangleGrid& grid() const { return grid_; }

 private:
  TriangleGrid grid_;
  TruthResult result_, self_result_;
};

/// The reference: every vertex against every triangle of every other body.
TruthResult groundTruthBruteForce(const std::vector<TruthBody>& bodies, const TruthSettings& settings);

/// The reference for computeSelf: every vertex against every triangle of its own body.
TruthResult groundTruthSelfBruteForce(const std::vector<TruthBody>& bodies, const SelfRule& rule,
                                      const TruthSettings& settings);

/// Vertices inside another closed body deeper than the strict radius (margin_A + margin_B): the
/// user-visible failure. Inside = odd crossings along +x and along +y (two rays, so that a ray
/// grazing an edge cannot fake an inside); depth = distance to that body's surface.
/// `grid` only keeps measurePenetration's buffers between calls (per-body RayColumns and distance
/// grids); the triangle grid itself is not built by it. The result is the one of the rays and
/// the distance search of TriangleGrid (rayParityOdd, nearestDistance) over the same bodies.
struct Penetration {
  double max_depth = 0.0;       ///< length units
  std::size_t vertices = 0;     ///< (vertex, body) pairs found penetrating
};
Penetration measurePenetration(const std::vector<TruthBody>& bodies, TriangleGrid& grid);

}  // namespace psc::demo
