#include "ground_truth.h"

#include <algorithm>
#include <cmath>
#include <limits>

namespace psc::demo {
namespace {

double segmentDistanceSquared(const Vec3& p, const Vec3& a, const Vec3& b) {
  const Vec3 ab = b - a;
  const double len2 = ab.squaredNorm();
  const double t = len2 > 0.0 ? std::clamp((p - a).dot(ab) / len2, 0.0, 1.0) : 0.0;
  return (p - (a + t * ab)).squaredNorm();
}

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

double pointTriangleDistanceSquared(const Vec3& p, const Vec3& a, const Vec3& b, const Vec3& c) {
  const Vec3 ab = b - a, ac = c - a;
  const double n2 = ab.cross(ac).squaredNorm();
  if (!(n2 > 1e-24 * ab.squaredNorm() * ac.squaredNorm()) || n2 == 0.0)
    return std::min({segmentDistanceSquared(p, a, b), segmentDistanceSquared(p, b, c), segmentDistanceSquared(p, c, a)});
  const Vec3 ap = p - a;
  const double d1 = ab.dot(ap), d2 = ac.dot(ap);
  if (d1 <= 0.0 && d2 <= 0.0) return ap.squaredNorm();
  const Vec3 bp = p - b;
  const double d3 = ab.dot(bp), d4 = ac.dot(bp);
  if (d3 >= 0.0 && d4 <= d3) return bp.squaredNorm();
  const double vc = d1 * d4 - d3 * d2;
  if (vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0) return (p - (a + (d1 / (d1 - d3)) * ab)).squaredNorm();
  const Vec3 cp = p - c;
  const double d5 = ab.dot(cp), d6 = ac.dot(cp);
  if (d6 >= 0.0 && d5 <= d6) return cp.squaredNorm();
  const double vb = d5 * d2 - d1 * d6;
  if (vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0) return (p - (a + (d2 / (d2 - d6)) * ac)).squaredNorm();
  const double va = d3 * d6 - d5 * d4;
  if (va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0)
    return (p - (b + ((d4 - d3) / ((d4 - d3) + (d5 - d6))) * (c - b))).squaredNorm();
  const double denom = 1.0 / (va + vb + vc);
  return (p - (a + ab * (vb * denom) + ac * (vc * denom))).squaredNorm();
}

const TruthContact* TruthResult::find(const ContactKey& key) const {
  auto it = std::lower_bound(contacts.begin(), contacts.end(), key,
                             [](const TruthContact& c, const ContactKey& k) { return c.key < k; });
  return it != contacts.end() && it->key == key ? &*it : nullptr;
}

// --- grid ---

std::uint32_t TriangleGrid::nextStamp() const {
  if (++stamp_now_ == 0) {  // wrapped: forget every old stamp
    std::fill(stamp_.begin(), stamp_.end(), 0u);
    stamp_now_ = 1;
  }
  return stamp_now_;
}

void TriangleGrid::build(const std::vector<TruthBody>& bodies, double cell) {
  bodies_ = &bodies;
  tri_body_.clear();
  tri_local_.clear();
  tri_lo_.clear();
  tri_hi_.clear();
  body_lo_.assign(bodies.size(), Vec3::Constant(std::numeric_limits<double>::infinity()));
  body_hi_.assign(bodies.size(), Vec3::Constant(-std::numeric_limits<double>::infinity()));
  double edge_sum = 0.0;
  std::size_t edge_count = 0;
  Vec3 lo = Vec3::Constant(std::numeric_limits<double>::infinity()), hi = -lo;
  for (std::size_t b = 0; b < bodies.size(); ++b) {
    const TruthBody& body = bodies[b];
    for (std::size_t t = 0; t < body.triangles.size(); ++t) {
      const Triangle& tri = body.triangles[t];
      const Vec3 &p0 = body.x[tri[0]], &p1 = body.x[tri[1]], &p2 = body.x[tri[2]];
      const Vec3 tl = p0.cwiseMin(p1).cwiseMin(p2), th = p0.cwiseMax(p1).cwiseMax(p2);
      tri_body_.push_back(static_cast<Index>(b));
      tri_local_.push_back(static_cast<Index>(t));
      tri_lo_.push_back(tl);
      tri_hi_.push_back(th);
      body_lo_[b] = body_lo_[b].cwiseMin(tl);
      body_hi_[b] = body_hi_[b].cwiseMax(th);
      edge_sum += (p1 - p0).norm() + (p2 - p1).norm() + (p0 - p2).norm();
      edge_count += 3;
    }
    lo = lo.cwiseMin(body_lo_[b]);
    hi = hi.cwiseMax(body_hi_[b]);
  }
  const std::size_t n = tri_body_.size();
  stamp_.assign(n, 0u);
  stamp_now_ = 0;
  if (n == 0) {
    origin_ = Vec3::Zero();
    dims_[0] = dims_[1] = dims_[2] = 1;
    offsets_.assign(2, 0u);
    items_.clear();
    return;
  }
  const Vec3 extent = (hi - lo).cwiseMax(Vec3::Constant(1e-12));
  cell_ = cell > 0.0 ? cell : std::max(edge_sum / static_cast<double>(edge_count), 1e-9 * extent.maxCoeff());
  // Dense cells, but never many more than triangles: scattered bodies would otherwise blow up.
  const double cap = 2.0 * static_cast<double>(n) + 64.0;
  for (;;) {
    for (int k = 0; k < 3; ++k) dims_[k] = static_cast<std::int64_t>(std::floor(extent[k] / cell_)) + 1;
    if (static_cast<double>(dims_[0]) * static_cast<double>(dims_[1]) * static_cast<double>(dims_[2]) <= cap) break;
    cell_ *= 1.26;
  }
  origin_ = lo;
  const std::size_t cells = static_cast<std::size_t>(dims_[0] * dims_[1] * dims_[2]);
  offsets_.assign(cells + 1, 0u);
  std::int64_t r[6];
  for (std::size_t g = 0; g < n; ++g) {
    cellRange(tri_lo_[g], tri_hi_[g], r);
    for (std::int64_t z = r[2]; z <= r[5]; ++z)
      for (std::int64_t y = r[1]; y <= r[4]; ++y)
        for (std::int64_t x = r[0]; x <= r[3]; ++x) ++offsets_[cellIndex(x, y, z) + 1];
  }
  for (std::size_t c = 0; c < cells; ++c) offsets_[c + 1] += offsets_[c];
  items_.resize(offsets_[cells]);
  std::vector<std::uint32_t> fill(offsets_.begin(), offsets_.end() - 1);
  for (std::size_t g = 0; g < n; ++g) {
    cellRange(tri_lo_[g], tri_hi_[g], r);
    for (std::int64_t z = r[2]; z <= r[5]; ++z)
      for (std::int64_t y = r[1]; y <= r[4]; ++y)
        for (std::int64_t x = r[0]; x <= r[3]; ++x) items_[fill[cellIndex(x, y, z)]++] = static_cast<std::uint32_t>(g);
  }
}

bool TriangleGrid::cellRange(const Vec3& lo, const Vec3& hi, std::int64_t r[6]) const {
  for (int k = 0; k < 3; ++k) {
    const double a = std::floor((lo[k] - origin_[k]) / cell_);
    const double b = std::floor((hi[k] - origin_[k]) / cell_);
    if (!(b >= 0.0) || !(a < static_cast<double>(dims_[k]))) return false;  // also rejects NaN
    r[k] = std::max<std::int64_t>(0, static_cast<std::int64_t>(a));
    r[k + 3] = std::min<std::int64_t>(dims_[k] - 1, static_cast<std::int64_t>(b));
  }
  return true;
}

bool TriangleGrid::rayParityOdd(const Vec3& p, Index body, int axis) const {
  const int u = (axis + 1) % 3, w = (axis + 2) % 3;
  std::int64_t r[6];
  Vec3 far = p;
  far[axis] = origin_[axis] + cell_ * static_cast<double>(dims_[axis]);
  if (!cellRange(p, far, r)) return false;
  const auto& B = (*bodies_)[body];
  const std::uint32_t s = nextStamp();
  bool odd = false;
  std::int64_t c[3] = {r[0], r[1], r[2]};
  for (std::int64_t i = r[axis]; i <= r[axis + 3]; ++i) {
    c[axis] = i;
    const std::size_t cell = cellIndex(c[0], c[1], c[2]);
    for (std::uint32_t k = offsets_[cell]; k < offsets_[cell + 1]; ++k) {
      const std::uint32_t g = items_[k];
      if (tri_body_[g] != body || stamp_[g] == s) continue;
      stamp_[g] = s;
      if (tri_hi_[g][axis] < p[axis] || tri_lo_[g][u] > p[u] || tri_hi_[g][u] < p[u] || tri_lo_[g][w] > p[w] ||
          tri_hi_[g][w] < p[w])
        continue;
      const Triangle& t = B.triangles[tri_local_[g]];
      Vec3 v[3] = {B.x[t[0]], B.x[t[1]], B.x[t[2]]};
      double area = (v[1][u] - v[0][u]) * (v[2][w] - v[0][w]) - (v[1][w] - v[0][w]) * (v[2][u] - v[0][u]);
      if (area == 0.0) continue;  // seen edge-on: the ray grazes it
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
      if (!inside) continue;
      // e[k] is the weight of the vertex opposite edge k (edge k runs from v[k] to v[k+1]).
      const double hit = (e[1] * v[0][axis] + e[2] * v[1][axis] + e[0] * v[2][axis]) / (e[0] + e[1] + e[2]);
      if (hit > p[axis]) odd = !odd;
    }
  }
  return odd;
}

double TriangleGrid::nearestDistance(const Vec3& p, Index body, double start) const {
  const auto& B = (*bodies_)[body];
  const double limit = 4.0 * cell_ * static_cast<double>(std::max({dims_[0], dims_[1], dims_[2]})) +
                       (p - origin_).norm();
  double best2 = std::numeric_limits<double>::infinity();
  for (double R = std::max(start, 1e-12);; R *= 2.0) {
    forEachInBox(p - Vec3::Constant(R), p + Vec3::Constant(R), [&](Index b, Index t) {
      if (b != body) return;
      const Triangle& tri = B.triangles[t];
      best2 = std::min(best2, pointTriangleDistanceSquared(p, B.x[tri[0]], B.x[tri[1]], B.x[tri[2]]));
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
        const double d2 = pointTriangleDistanceSquared(p, B.x[tri[0]], B.x[tri[1]], B.x[tri[2]]);
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

TruthResult groundTruthBruteForce(const std::vector<TruthBody>& bodies, const TruthSettings& s) {
  TruthResult r;
  for (std::size_t a = 0; a < bodies.size(); ++a) {
    const TruthBody& A = bodies[a];
    for (std::size_t v = 0; v < A.x.size(); ++v) {
      const Vec3& p = A.x[v];
      const double motion = s.full ? 2.0 * (p - A.prev[v]).norm() : 0.0;
      for (std::size_t b = 0; b < bodies.size(); ++b) {
        if (b == a) continue;
        const TruthBody& B = bodies[b];
        const double rs = A.margin + B.margin, rf = rs + motion;
        for (std::size_t t = 0; t < B.triangles.size(); ++t) {
          const Triangle& tri = B.triangles[t];
          const double d = std::sqrt(pointTriangleDistanceSquared(p, B.x[tri[0]], B.x[tri[1]], B.x[tri[2]]));
          ++r.distance_tests;
          pushIfAny(r.contacts, {static_cast<Index>(a), static_cast<Index>(v), static_cast<Index>(b), static_cast<Index>(t)},
                    d, rs, rf, s);
        }
      }
    }
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
