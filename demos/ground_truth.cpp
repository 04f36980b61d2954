#include "ground_truth.h"

#include "psc/mesh.h"
#include "psc/testkit/reference.h"
#include "psc/world.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>

namespace psc::demo {
namespace {

Membership classify(double d, double r, const TruthSettings& s) {
  const double band = s.band_relative * r + s.band_absolute;
  if (d < r - band) return Membership::Inside;
  if (d > r + band) return Membership::Outside;
  return Membership::Ambiguous;
}

double band(double r, const TruthSettings& s) { return s.band_relative * r + s.band_absolute; }

bool boxesOverlap(const Vec3& alo, const Vec3& ahi, const Vec3& blo, const Vec3& bhi) {
  return alo.x() <= bhi.x() && alo.y() <= bhi.y() && alo.z() <= bhi.z() && blo.x() <= ahi.x() &&
         blo.y() <= ahi.y() && blo.z() <= ahi.z();
}

void pushIfAny(std::vector<TruthContact>& out, const ContactKey& key, double d, double strict_r, double full_r,
               const TruthSettings& s) {
  TruthContact c;
  c.key = key;
  c.distance = d;
  if (s.strict) c.strict = classify(d, strict_r, s);
  if (s.full) c.full = classify(d, full_r, s);
  if (c.strict != Membership::Outside || c.full != Membership::Outside) out.push_back(c);
}

void countUp(TruthResult& r) {
  r.strict_inside = r.strict_ambiguous = r.full_inside = r.full_ambiguous = 0;
  for (const TruthContact& c : r.contacts) {
    r.strict_inside += c.strict == Membership::Inside;
    r.strict_ambiguous += c.strict == Membership::Ambiguous;
    r.full_inside += c.full == Membership::Inside;
    r.full_ambiguous += c.full == Membership::Ambiguous;
  }
}

double maxMargin(const std::vector<TruthBody>& bodies) {
  double m = 0.0;
  for (const TruthBody& b : bodies) m = std::max(m, b.margin);
  return m;
}

/// Whether the ray from p along +axis crosses triangle (c0, c1, c2), whose box the ray meets
/// (spans p across the axis and reaches p along it). Both ray casts (TriangleGrid and
/// RayColumns) count with this one function, so they agree bit for bit, ties included.
bool rayCrosses(const Vec3& p, const Vec3& c0, const Vec3& c1, const Vec3& c2, int axis) {
  const int u = (axis + 1) % 3, w = (axis + 2) % 3;
  Vec3 v[3] = {c0, c1, c2};
  double area = (v[1][u] - v[0][u]) * (v[2][w] - v[0][w]) - (v[1][w] - v[0][w]) * (v[2][u] - v[0][u]);
  if (area == 0.0) return false;  // seen edge-on: the ray grazes it
  if (area < 0.0) {
    std::swap(v[1], v[2]);
    area = -area;
  }
  // Edge functions with a tie rule that gives a point on a shared edge (or vertex) to exactly
  // one of the triangles on either side, so a watertight surface is crossed once, not 0 or 2.
  double e[3];
  for (int j = 0; j < 3; ++j) {
    const Vec3& a = v[j];
    const Vec3& b = v[(j + 1) % 3];
    const double du = b[u] - a[u], dw = b[w] - a[w];
    e[j] = du * (p[w] - a[w]) - dw * (p[u] - a[u]);
    if (e[j] < 0.0 || (e[j] == 0.0 && !(dw < 0.0 || (dw == 0.0 && du > 0.0)))) return false;
  }
  // e[k] is the weight of the vertex opposite edge k (edge k runs from v[k] to v[k+1]).
  const double hit = (e[1] * v[0][axis] + e[2] * v[1][axis] + e[0] * v[2][axis]) / (e[0] + e[1] + e[2]);
  return hit > p[axis];
}

}  // namespace

const TruthContact* TruthResult::find(const ContactKey& key) const {
  auto it = std::lower_bound(contacts.begin(), contacts.end(), key,
                             [](const TruthContact& c, const ContactKey& k) { return c.key < k; });
  return it != contacts.end() && it->key == key ? &*it : nullptr;
}

// --- grid ---

void TriangleGrid::build(const std::vector<TruthBody>& bodies, double cell) {
  bodies_ = &bodies;
  std::size_t triangles = 0;
  for (const TruthBody& body : bodies) triangles += body.triangles.size();
  tri_body_.clear();
  tri_local_.clear();
  tri_body_.reserve(triangles);
  tri_local_.reserve(triangles);
  std::vector<testkit::Box> boxes;
  boxes.reserve(triangles);
  body_lo_.assign(bodies.size(), Vec3::Constant(std::numeric_limits<double>::infinity()));
  body_hi_.assign(bodies.size(), Vec3::Constant(-std::numeric_limits<double>::infinity()));
  double edge_sum = 0.0;
  std::size_t edge_count = 0;
  for (std::size_t b = 0; b < bodies.size(); ++b) {
    const TruthBody& body = bodies[b];
    for (std::size_t t = 0; t < body.triangles.size(); ++t) {
      const Triangle& tri = body.triangles[t];
      const Vec3 &p0 = body.x[tri[0]], &p1 = body.x[tri[1]], &p2 = body.x[tri[2]];
      const Vec3 tl = p0.cwiseMin(p1).cwiseMin(p2), th = p0.cwiseMax(p1).cwiseMax(p2);
      tri_body_.push_back(static_cast<Index>(b));
      tri_local_.push_back(static_cast<Index>(t));
      boxes.push_back({tl, th});
      body_lo_[b] = body_lo_[b].cwiseMin(tl);
      body_hi_[b] = body_hi_[b].cwiseMax(th);
      edge_sum += (p1 - p0).norm() + (p2 - p1).norm() + (p0 - p2).norm();
      edge_count += 3;
    }
  }
  const double mean_edge = edge_sum / static_cast<double>(std::max<std::size_t>(edge_count, 1));
  grid_.build(std::move(boxes), cell > 0.0 ? cell : mean_edge);
}

bool TriangleGrid::rayParityOdd(const Vec3& p, Index body, int axis) const {
  const int u = (axis + 1) % 3, w = (axis + 2) % 3;
  Vec3 far = p;
  far[axis] = grid_.origin()[axis] + grid_.cellSize() * static_cast<double>(grid_.dims()[axis]);
  const auto& B = (*bodies_)[body];
  bool odd = false;
  // The column of cells from p to the grid's end; the ray meets a box iff it spans p across axis.
  grid_.forEachInCells(p, far, [&](Index g) {
    const testkit::Box& box = grid_.box(g);
    if (tri_body_[g] != body || box.hi[axis] < p[axis] || box.lo[u] > p[u] || box.hi[u] < p[u] || box.lo[w] > p[w] ||
        box.hi[w] < p[w])
      return;
    const Triangle& t = B.triangles[tri_local_[g]];
    if (rayCrosses(p, B.x[t[0]], B.x[t[1]], B.x[t[2]], axis)) odd = !odd;
  });
  return odd;
}

double TriangleGrid::nearestDistance(const Vec3& p, Index body, double start) const {
  const auto& B = (*bodies_)[body];
  const auto& dims = grid_.dims();
  const double limit = 4.0 * grid_.cellSize() * static_cast<double>(std::max({dims[0], dims[1], dims[2]})) +
                       (p - grid_.origin()).norm();
  double best2 = std::numeric_limits<double>::infinity();
  for (double R = std::max(start, 1e-12);; R *= 2.0) {
    forEachInBox(p - Vec3::Constant(R), p + Vec3::Constant(R), [&](Index b, Index t) {
      if (b != body) return;
      const Triangle& tri = B.triangles[t];
      best2 = std::min(best2, testkit::pointTriangleDistanceSquared(p, B.x[tri[0]], B.x[tri[1]], B.x[tri[2]]));
    });
    if (best2 <= R * R || R > limit) return std::sqrt(best2);
  }
}

// --- penetration ---

void RayColumns::build(const TruthBody& body, int axis) {
  axis_ = axis;
  const int u = (axis + 1) % 3, w = (axis + 2) % 3;
  constexpr double inf = std::numeric_limits<double>::infinity();
  pending_.clear();
  pending_.reserve(body.triangles.size());
  double lo_u = inf, hi_u = -inf, lo_w = inf, hi_w = -inf, extent_sum = 0.0;
  for (std::size_t t = 0; t < body.triangles.size(); ++t) {
    const Triangle& tri = body.triangles[t];
    const Vec3 &p0 = body.x[tri[0]], &p1 = body.x[tri[1]], &p2 = body.x[tri[2]];
    // The box exactly as TriangleGrid::build makes it (and BoxGrid leaves out a NaN one).
    const Vec3 tl = p0.cwiseMin(p1).cwiseMin(p2), th = p0.cwiseMax(p1).cwiseMax(p2);
    if (tl.hasNaN() || th.hasNaN()) continue;
    pending_.push_back({tl[u], th[u], tl[w], th[w], static_cast<Index>(t)});
    lo_u = std::min(lo_u, tl[u]);
    hi_u = std::max(hi_u, th[u]);
    lo_w = std::min(lo_w, tl[w]);
    hi_w = std::max(hi_w, th[w]);
    extent_sum += (th[u] - tl[u]) + (th[w] - tl[w]);
  }
  if (pending_.empty()) {
    nu_ = nw_ = 0;  // no ray crosses anything
    return;
  }
  origin_u_ = lo_u;
  origin_w_ = lo_w;
  const double n = static_cast<double>(pending_.size());
  const double extent_u = hi_u - lo_u, extent_w = hi_w - lo_w;
  if (!std::isfinite(extent_u) || !std::isfinite(extent_w)) {
    // Exploded coordinates: one cell holding everything is still exact.
    cell_ = inv_cell_ = 1.0;
    nu_ = nw_ = 1;
  } else {
    // Cells narrower than a triangle's box: a triangle goes into 1 to 4 of them, and a query's
    // 2×2 cells hold few more triangles than the ones its ray meets. At most about two cells
    // per triangle, so that a few huge triangles cannot blow the grid up.
    cell_ = std::max(kCellPerBox * extent_sum / (2.0 * n), 1e-9 * std::max(extent_u, extent_w));
    if (!(cell_ > 0.0)) cell_ = 1.0;  // every box a single point
    for (;;) {
      nu_ = static_cast<std::int64_t>(std::floor(extent_u / cell_)) + 1;
      nw_ = static_cast<std::int64_t>(std::floor(extent_w / cell_)) + 1;
      if (static_cast<double>(nu_) * static_cast<double>(nw_) <= 2.0 * n + 64.0) break;
      cell_ *= 1.26;
    }
    inv_cell_ = 1.0 / cell_;
  }
  // Two passes, count then fill. A triangle over cells [i0, i1] × [j0, j1] goes into (i0, j0) and
  // every other cell from there: of the 2×2 cells a query reads, (i−1..i) × (j−1..j), exactly
  // one holds it whenever i0 ≤ i ≤ i1 and j0 ≤ j ≤ j1. The cell of a coordinate only grows with
  // it, so the query's cell is within the range of every box that spans the query point.
  offsets_.assign(static_cast<std::size_t>(nu_ * nw_) + 1, 0u);
  for (const Pending& t : pending_) {
    const std::int64_t i0 = cellU(t.lo_u), i1 = cellU(t.hi_u), j0 = cellW(t.lo_w), j1 = cellW(t.hi_w);
    for (std::int64_t j = j0; j <= j1; j += 2)
      for (std::int64_t i = i0; i <= i1; i += 2) ++offsets_[static_cast<std::size_t>(j * nu_ + i) + 1];
  }
  for (std::size_t c = 1; c < offsets_.size(); ++c) offsets_[c] += offsets_[c - 1];
  // Grown, never shrunk nor zeroed: every slot up to offsets_.back() is written below.
  if (items_.size() < offsets_.back()) items_.resize(offsets_.back());
  if (corners_.size() < pending_.size()) corners_.resize(pending_.size());
  fill_.assign(offsets_.begin(), offsets_.end() - 1);
  for (std::size_t k = 0; k < pending_.size(); ++k) {
    const Pending& t = pending_[k];
    const Triangle& tri = body.triangles[t.triangle];
    double* c = corners_[k].c;
    for (int m = 0; m < 3; ++m) {
      const Vec3& v = body.x[tri[m]];
      c[3 * m] = v[u];
      c[3 * m + 1] = v[w];
      c[3 * m + 2] = v[axis];
    }
    const Item item{testkit::floatBelow(t.lo_u), testkit::floatAbove(t.hi_u), testkit::floatBelow(t.lo_w), testkit::floatAbove(t.hi_w),
                    testkit::floatAbove(std::max({c[2], c[5], c[8]})), static_cast<std::uint32_t>(k)};
    const std::int64_t i0 = cellU(t.lo_u), i1 = cellU(t.hi_u), j0 = cellW(t.lo_w), j1 = cellW(t.hi_w);
    for (std::int64_t j = j0; j <= j1; j += 2)
      for (std::int64_t i = i0; i <= i1; i += 2) items_[fill_[static_cast<std::size_t>(j * nu_ + i)]++] = item;
  }
}

std::int64_t RayColumns::cellU(double x) const {
  const double t = (x - origin_u_) * inv_cell_;
  if (!(t > 0.0)) return 0;
  return t < static_cast<double>(nu_) ? static_cast<std::int64_t>(t) : nu_ - 1;
}

std::int64_t RayColumns::cellW(double x) const {
  const double t = (x - origin_w_) * inv_cell_;
  if (!(t > 0.0)) return 0;
  return t < static_cast<double>(nw_) ? static_cast<std::int64_t>(t) : nw_ - 1;
}

bool RayColumns::parityOdd(const Vec3& p) const {
  if (nu_ == 0 || p.hasNaN()) return false;  // a NaN is in no cell of TriangleGrid either
  const int u = (axis_ + 1) % 3, w = (axis_ + 2) % 3;
  // p in (u, w, axis) order, as the corners are stored: rayCrosses along +z then does on these
  // numbers exactly what it does along +axis on the original ones.
  const Vec3 q(p[u], p[w], p[axis_]);
  const std::int64_t i = cellU(q[0]), j = cellW(q[1]);
  const std::int64_t i_first = std::max<std::int64_t>(i - 1, 0);
  bool odd = false;
  for (std::int64_t jj = std::max<std::int64_t>(j - 1, 0); jj <= j; ++jj) {
    // Cells (i−1, jj) and (i, jj) are neighbours in the CSR: one run of items.
    const std::uint32_t first = offsets_[static_cast<std::size_t>(jj * nu_ + i_first)];
    const std::uint32_t last = offsets_[static_cast<std::size_t>(jj * nu_ + i) + 1];
    for (std::uint32_t k = first; k < last; ++k) {
      const Item& it = items_[k];
      // Five comparisons and one branch: most items fail, on no predictable one of them.
      if (!((it.hi_a >= q[2]) & (it.lo_u <= q[0]) & (it.hi_u >= q[0]) & (it.lo_w <= q[1]) & (it.hi_w >= q[1])))
        continue;
      const double* c = corners_[it.corners].c;
      // TriangleGrid::rayParityOdd's box test, on the same (exact) box.
      if (std::max({c[2], c[5], c[8]}) < q[2] || std::min({c[0], c[3], c[6]}) > q[0] ||
          std::max({c[0], c[3], c[6]}) < q[0] || std::min({c[1], c[4], c[7]}) > q[1] ||
          std::max({c[1], c[4], c[7]}) < q[1])
        continue;
      if (rayCrosses(q, Vec3(c[0], c[1], c[2]), Vec3(c[3], c[4], c[5]), Vec3(c[6], c[7], c[8]), 2)) odd = !odd;
    }
  }
  return odd;
}

bool TriangleGrid::PenetrationBody::deeperThan(const TruthBody& body, const Vec3& p, double strict, double& depth) {
  if (!distance_built) {
    distance_built = true;
    std::vector<testkit::Box> boxes;
    boxes.reserve(body.triangles.size());
    visible_lo = Vec3::Constant(std::numeric_limits<double>::infinity());
    visible_hi = -visible_lo;
    any_visible = false;
    double edge_sum = 0.0;
    for (const Triangle& tri : body.triangles) {
      const Vec3 &p0 = body.x[tri[0]], &p1 = body.x[tri[1]], &p2 = body.x[tri[2]];
      const Vec3 tl = p0.cwiseMin(p1).cwiseMin(p2), th = p0.cwiseMax(p1).cwiseMax(p2);
      boxes.push_back({tl, th});
      edge_sum += (p1 - p0).norm() + (p2 - p1).norm() + (p0 - p2).norm();
      if (tl.hasNaN() || th.hasNaN()) continue;  // in no cell of the grid
      visible_lo = visible_lo.cwiseMin(tl);
      visible_hi = visible_hi.cwiseMax(th);
      any_visible = true;
    }
    distance.build(std::move(boxes), 3.0 * edge_sum / static_cast<double>(3 * std::max<std::size_t>(body.triangles.size(), 1)));
  }
  if (!any_visible) {
    depth = std::numeric_limits<double>::infinity();  // what nearestDistance finds: nothing
    return depth > strict;
  }
  const auto distance2 = [&](Index t) {
    const Triangle& tri = body.triangles[t];
    return testkit::pointTriangleDistanceSquared(p, body.x[tri[0]], body.x[tri[1]], body.x[tri[2]]);
  };
  const double R0 = std::max(strict, 1e-12);
  if (R0 == strict) {
    // Most vertices found inside lie within the margins (a contact being resolved). One triangle
    // of the first cube (its box meets it) at distance ≤ R0 settles that: nearestDistance stops
    // at that cube with a distance ≤ R0 = strict, so the vertex is not counted, and its depth is
    // not needed. Look for one, cheaply: triangles whose box is farther than R0 cannot be it.
    bool near = false;
    distance.forEachInBox(p - Vec3::Constant(R0), p + Vec3::Constant(R0), [&](Index t) {
      if (near) return;
      const testkit::Box& box = distance.box(t);
      double box2 = 0.0;
      for (int k = 0; k < 3; ++k) {
        const double gap = std::max({box.lo[k] - p[k], 0.0, p[k] - box.hi[k]});
        box2 += gap * gap;
      }
      near = box2 <= R0 * R0 && distance2(t) <= R0 * R0;
    });
    if (near) {
      depth = R0;
      return false;
    }
  }
  // TriangleGrid::nearestDistance's search: the same radii, and at each the same triangles (those
  // whose box meets the cube), so the same minimum. It stops at its grid's far end; this one once
  // the cube holds every box, where the minimum can no longer change: the same result. The
  // triangles of the last cube are in the minimum already: not computed again.
  double best2 = std::numeric_limits<double>::infinity();
  testkit::Box last{Vec3::Constant(std::numeric_limits<double>::quiet_NaN()), Vec3::Zero()};  // meets nothing
  for (double R = R0;; R *= 2.0) {
    const Vec3 cube_lo = p - Vec3::Constant(R), cube_hi = p + Vec3::Constant(R);
    distance.forEachInBox(cube_lo, cube_hi, [&](Index t) {
      if (!distance.box(t).meets(last)) best2 = std::min(best2, distance2(t));
    });
    last = {cube_lo, cube_hi};
    if (best2 <= R * R ||
        ((cube_lo.array() <= visible_lo.array()).all() && (cube_hi.array() >= visible_hi.array()).all())) {
      depth = std::sqrt(best2);
      return depth > strict;
    }
  }
}

// --- truth ---

const TruthResult& GroundTruth::compute(const std::vector<TruthBody>& bodies, const TruthSettings& s) {
  result_.contacts.clear();
  result_.distance_tests = 0;
  grid_.build(bodies);
  const double other_margin = maxMargin(bodies);
  for (std::size_t a = 0; a < bodies.size(); ++a) {
    const TruthBody& A = bodies[a];
    if (A.x.empty()) continue;
    // Which bodies can A's vertices reach at all (boxes grown by the largest query radius)?
    double max_motion = 0.0;
    Vec3 alo = A.x[0], ahi = A.x[0];
    for (std::size_t v = 0; v < A.x.size(); ++v) {
      alo = alo.cwiseMin(A.x[v]);
      ahi = ahi.cwiseMax(A.x[v]);
      if (s.full) max_motion = std::max(max_motion, 2.0 * (A.x[v] - A.prev[v]).norm());
    }
    const double max_q = A.margin + other_margin + max_motion;
    const Vec3 grow = Vec3::Constant(max_q + band(max_q, s));
    std::vector<Index> near;
    for (std::size_t b = 0; b < bodies.size(); ++b)
      if (b != a && !bodies[b].triangles.empty() &&
          boxesOverlap(alo - grow, ahi + grow, grid_.body_lo_[b], grid_.body_hi_[b]))
        near.push_back(static_cast<Index>(b));
    if (near.empty()) continue;
    for (std::size_t v = 0; v < A.x.size(); ++v) {
      const Vec3& p = A.x[v];
      const double motion = s.full ? 2.0 * (p - A.prev[v]).norm() : 0.0;
      double q = A.margin + other_margin + motion;
      q += band(q, s);
      const Vec3 qlo = p - Vec3::Constant(q), qhi = p + Vec3::Constant(q);
      bool any = false;
      for (Index b : near) any = any || boxesOverlap(qlo, qhi, grid_.body_lo_[b], grid_.body_hi_[b]);
      if (!any) continue;
      grid_.forEachInBox(qlo, qhi, [&](Index b, Index t) {
        if (b == a) return;
        const TruthBody& B = bodies[b];
        const double rs = A.margin + B.margin, rf = rs + motion;
        const double rmax = s.full ? rf : rs;
        const double reach = rmax + band(rmax, s);
        const Triangle& tri = B.triangles[t];
        const double d2 = testkit::pointTriangleDistanceSquared(p, B.x[tri[0]], B.x[tri[1]], B.x[tri[2]]);
        ++result_.distance_tests;
        if (d2 > reach * reach) return;
        pushIfAny(result_.contacts, {static_cast<Index>(a), static_cast<Index>(v), b, t}, std::sqrt(d2), rs, rf, s);
      });
    }
  }
  std::sort(result_.contacts.begin(), result_.contacts.end(),
            [](const TruthContact& x, const TruthContact& y) { return x.key < y.key; });
  countUp(result_);
  return result_;
}

double SelfRule::radius(const TruthBody& body, std::size_t b) const {
  return selfContactRadius(body.margin, rest_mean_edge.at(b), radius_edges);
}

SelfRule selfRule(const std::vector<std::vector<Triangle>>& triangles, std::vector<std::vector<Vec3>> rest) {
  if (triangles.size() != rest.size())
    throw std::invalid_argument("selfRule: " + std::to_string(triangles.size()) + " meshes but " +
                                std::to_string(rest.size()) + " rest shapes");
  SelfRule rule;
  const SensorSettings defaults;
  rule.rest_exclusion = defaults.self_rest_exclusion;
  rule.radius_edges = defaults.self_radius_edges;
  for (std::size_t b = 0; b < rest.size(); ++b)
    rule.rest_mean_edge.push_back(edgeStats(MeshTopology(triangles[b], rest[b].size()), PositionView::of(rest[b])).mean);
  rule.rest = std::move(rest);
  return rule;
}

Vec3 meanDisplacement(const TruthBody& body) {
  std::vector<char> used(body.x.size(), 0);
  for (const Triangle& t : body.triangles)
    for (Index v : t) used[v] = 1;
  Vec3 sum = Vec3::Zero();
  double n = 0.0;
  for (std::size_t v = 0; v < body.x.size(); ++v)
    if (used[v]) {
      sum += body.x[v] - body.prev[v];
      n += 1.0;
    }
  return n > 0.0 ? Vec3(sum / n) : Vec3::Zero();
}

const TruthResult& GroundTruth::computeSelf(const std::vector<TruthBody>& bodies, const SelfRule& rule,
                                            const TruthSettings& s) {
  self_result_.contacts.clear();
  self_result_.distance_tests = 0;
  grid_.build(bodies);
  for (std::size_t a = 0; a < bodies.size(); ++a) {
    const TruthBody& A = bodies[a];
    const double rs = rule.radius(A, a);
    const Vec3 mean = meanDisplacement(A);
    for (std::size_t v = 0; v < A.x.size(); ++v) {
      const Vec3& p = A.x[v];
      const double motion = s.full ? 2.0 * selfMotion(p - A.prev[v], mean) : 0.0;
      const double rf = rs + motion, rmax = s.full ? rf : rs;
      const double reach = rmax + band(rmax, s);
      grid_.forEachInBox(p - Vec3::Constant(reach), p + Vec3::Constant(reach), [&](Index b, Index t) {
        if (b != a) return;
        const Triangle& tri = A.triangles[t];
        if (tri[0] == v || tri[1] == v || tri[2] == v) return;
        const double d2 = testkit::pointTriangleDistanceSquared(p, A.x[tri[0]], A.x[tri[1]], A.x[tri[2]]);
        ++self_result_.distance_tests;
        if (d2 > reach * reach || testkit::selfPairExcluded(static_cast<Index>(v), tri, rule.rest[a], rs, rule.rest_exclusion))
          return;
        pushIfAny(self_result_.contacts, {static_cast<Index>(a), static_cast<Index>(v), b, t}, std::sqrt(d2), rs, rf, s);
      });
    }
  }
  std::sort(self_result_.contacts.begin(), self_result_.contacts.end(),
            [](const TruthContact& x, const TruthContact& y) { return x.key < y.key; });
  countUp(self_result_);
  return self_result_;
}

TruthResult groundTruthBruteForce(const std::vector<TruthBody>& bodies, const TruthSettings& s) {
  TruthResult r;
  for (std::size_t a = 0; a < bodies.size(); ++a) {
    const TruthBody& A = bodies[a];
    const auto motion = [&](Index v) { return s.full ? 2.0 * (A.x[v] - A.prev[v]).norm() : 0.0; };
    for (std::size_t b = 0; b < bodies.size(); ++b) {
      if (b == a) continue;
      const TruthBody& B = bodies[b];
      const double rs = A.margin + B.margin;
      // Every pair that is not Outside for an asked radius: distance ≤ reach, the largest r + band.
      const auto radius = [&](Index v) {
        const double rmax = s.full ? rs + motion(v) : rs;
        return std::nextafter(rmax + band(rmax, s), std::numeric_limits<double>::infinity());
      };
      testkit::forEachContact(A.x, B.x, B.triangles, radius, [&](Index v, Index t, double d) {
        pushIfAny(r.contacts, {static_cast<Index>(a), v, static_cast<Index>(b), t}, d, rs, rs + motion(v), s);
      });
      r.distance_tests += A.x.size() * B.triangles.size();
    }
  }
  std::sort(r.contacts.begin(), r.contacts.end(), [](const TruthContact& x, const TruthContact& y) { return x.key < y.key; });
  countUp(r);
  return r;
}

TruthResult groundTruthSelfBruteForce(const std::vector<TruthBody>& bodies, const SelfRule& rule,
                                      const TruthSettings& s) {
  TruthResult r;
  for (std::size_t a = 0; a < bodies.size(); ++a) {
    const TruthBody& A = bodies[a];
    const double rs = rule.radius(A, a);
    const Vec3 mean = meanDisplacement(A);
    const auto motion = [&](Index v) { return s.full ? 2.0 * selfMotion(A.x[v] - A.prev[v], mean) : 0.0; };
    const auto radius = [&](Index v) {
      const double rmax = s.full ? rs + motion(v) : rs;
      return std::nextafter(rmax + band(rmax, s), std::numeric_limits<double>::infinity());
    };
    const auto excluded = [&](Index v, Index t) {
      return testkit::selfPairExcluded(v, A.triangles[t], rule.rest[a], rs, rule.rest_exclusion);
    };
    testkit::forEachContact(A.x, A.x, A.triangles, radius, excluded, [&](Index v, Index t, double d) {
      pushIfAny(r.contacts, {static_cast<Index>(a), v, static_cast<Index>(a), t}, d, rs, rs + motion(v), s);
    });
    r.distance_tests += A.x.size() * A.triangles.size();
  }
  std::sort(r.contacts.begin(), r.contacts.end(), [](const TruthContact& x, const TruthContact& y) { return x.key < y.key; });
  countUp(r);
  return r;
}

Penetration measurePenetration(const std::vector<TruthBody>& bodies, TriangleGrid& grid) {
  // The same vertices, rays and depths as casting TriangleGrid's rays over one grid of all bodies
  // (rayParityOdd, nearestDistance), without that grid: a body pair whose boxes are apart costs
  // one pass over the vertices, and a ray reads only its column of the one body it is cast
  // against (RayColumns, built for a body when a vertex of another first lies in its box). The
  // +y ray is cast only after an odd +x one, so its columns are built only for a body something
  // seems to be inside.
  Penetration out;
  const std::size_t n = bodies.size();
  auto& pen = grid.pen_;
  pen.resize(n);
  constexpr double inf = std::numeric_limits<double>::infinity();
  for (std::size_t b = 0; b < n; ++b) {
    TriangleGrid::PenetrationBody& P = pen[b];
    P.box_built = P.columns_built[0] = P.columns_built[1] = P.distance_built = false;
    // The box of the vertices; a NaN coordinate is left out (such a vertex is in no cell of
    // TriangleGrid, so never inside anything), but noted.
    double lo[3] = {inf, inf, inf}, hi[3] = {-inf, -inf, -inf};
    bool nan = false;
    for (const Vec3& p : bodies[b].x)
      for (int k = 0; k < 3; ++k) {
        nan = nan || std::isnan(p[k]);
        if (p[k] < lo[k]) lo[k] = p[k];
        if (p[k] > hi[k]) hi[k] = p[k];
      }
    P.vertex_lo = Vec3(lo[0], lo[1], lo[2]);
    P.vertex_hi = Vec3(hi[0], hi[1], hi[2]);
    P.vertex_nan = nan;
  }
  // Every vertex of A on the far side of a face of [lo, hi] (B's box) fails the test below. (A
  // NaN bound compares false: no skip, as the test below skips nothing on it either.)
  const auto apart = [](const TriangleGrid::PenetrationBody& A, const Vec3& lo, const Vec3& hi) {
    bool out_of_box = false;
    for (int k = 0; k < 3; ++k) out_of_box = out_of_box || A.vertex_hi[k] <= lo[k] || A.vertex_lo[k] >= hi[k];
    return out_of_box;
  };
  for (std::size_t b = 0; b < n; ++b) {
    const TruthBody& B = bodies[b];
    if (!B.closed || B.triangles.empty()) continue;
    TriangleGrid::PenetrationBody& P = pen[b];
    const auto parityOdd = [&](const Vec3& p, int axis) {
      if (!P.columns_built[axis]) {
        P.columns[axis].build(B, axis);
        P.columns_built[axis] = true;
      }
      return P.columns[axis].parityOdd(p);
    };
    for (std::size_t a = 0; a < n; ++a) {
      if (a == b) continue;
      // First against the box of all of B's vertices, which holds the box of its triangles
      // (unless a NaN makes the latter's bounds a matter of Eigen's min and max).
      if (!P.vertex_nan && apart(pen[a], P.vertex_lo, P.vertex_hi)) continue;
      if (!P.box_built) {
        // B's box exactly as TriangleGrid::build computes body_lo_ and body_hi_.
        P.box_built = true;
        Vec3 lo = Vec3::Constant(inf), hi = Vec3::Constant(-inf);
        for (const Triangle& tri : B.triangles) {
          const Vec3 &p0 = B.x[tri[0]], &p1 = B.x[tri[1]], &p2 = B.x[tri[2]];
          lo = lo.cwiseMin(p0.cwiseMin(p1).cwiseMin(p2));
          hi = hi.cwiseMax(p0.cwiseMax(p1).cwiseMax(p2));
        }
        P.lo = lo;
        P.hi = hi;
      }
      const Vec3 &blo = P.lo, &bhi = P.hi;
      if (apart(pen[a], blo, bhi)) continue;
      const TruthBody& A = bodies[a];
      const double strict = A.margin + B.margin;
      for (const Vec3& p : A.x) {
        if (p.x() <= blo.x() || p.y() <= blo.y() || p.z() <= blo.z() || p.x() >= bhi.x() || p.y() >= bhi.y() ||
            p.z() >= bhi.z())
          continue;
        if (!parityOdd(p, 0) || !parityOdd(p, 1)) continue;
        double depth = 0.0;
        if (P.deeperThan(B, p, strict, depth)) {
          ++out.vertices;
          out.max_depth = std::max(out.max_depth, depth);
        }
      }
    }
  }
  return out;
}

}  // namespace psc::demo
