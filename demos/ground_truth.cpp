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

}  // namespace

const TruthContact* TruthResult::find(const ContactKey& key) const {
  auto it = std::lower_bound(contacts.begin(), contacts.end(), key,
                             [](const TruthContact& c, const ContactKey& k) { return c.key < k; });
  return it != contacts.end() && it->key == key ? &*it : nullptr;
}

// --- grid ---

void TriangleGrid::build(const std::vector<TruthBody>& bodies, double cell) {
  bodies_ = &bodies;
  tri_body_.clear();
  tri_local_.clear();
  std::vector<testkit::Box> boxes;
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
    Vec3 v[3] = {B.x[t[0]], B.x[t[1]], B.x[t[2]]};
    double area = (v[1][u] - v[0][u]) * (v[2][w] - v[0][w]) - (v[1][w] - v[0][w]) * (v[2][u] - v[0][u]);
    if (area == 0.0) return;  // seen edge-on: the ray grazes it
    if (area < 0.0) {
      std::swap(v[1], v[2]);
      area = -area;
    }
    // Edge functions with a tie rule that gives a point on a shared edge (or vertex) to exactly
    // one of the triangles on either side, so a watertight surface is crossed once, not 0 or 2.
    double e[3];
    bool inside = true;
    for (int j = 0; j < 3 && inside; ++j) {
      const Vec3& a = v[j];
      const Vec3& b = v[(j + 1) % 3];
      const double du = b[u] - a[u], dw = b[w] - a[w];
      e[j] = du * (p[w] - a[w]) - dw * (p[u] - a[u]);
      if (e[j] < 0.0 || (e[j] == 0.0 && !(dw < 0.0 || (dw == 0.0 && du > 0.0)))) inside = false;
    }
    if (!inside) return;
    // e[k] is the weight of the vertex opposite edge k (edge k runs from v[k] to v[k+1]).
    const double hit = (e[1] * v[0][axis] + e[2] * v[1][axis] + e[0] * v[2][axis]) / (e[0] + e[1] + e[2]);
    if (hit > p[axis]) odd = !odd;
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
  Penetration out;
  grid.build(bodies);
  for (std::size_t b = 0; b < bodies.size(); ++b) {
    const TruthBody& B = bodies[b];
    if (!B.closed || B.triangles.empty()) continue;
    const Vec3 &blo = grid.body_lo_[b], &bhi = grid.body_hi_[b];
    for (std::size_t a = 0; a < bodies.size(); ++a) {
      if (a == b) continue;
      const TruthBody& A = bodies[a];
      const double strict = A.margin + B.margin;
      for (const Vec3& p : A.x) {
        if (p.x() <= blo.x() || p.y() <= blo.y() || p.z() <= blo.z() || p.x() >= bhi.x() || p.y() >= bhi.y() ||
            p.z() >= bhi.z())
          continue;
        if (!grid.rayParityOdd(p, static_cast<Index>(b), 0) || !grid.rayParityOdd(p, static_cast<Index>(b), 1)) continue;
        const double depth = grid.nearestDistance(p, static_cast<Index>(b), strict);
        if (depth > strict) {
          ++out.vertices;
          out.max_depth = std::max(out.max_depth, depth);
        }
      }
    }
  }
  return out;
}

}  // namespace psc::demo
