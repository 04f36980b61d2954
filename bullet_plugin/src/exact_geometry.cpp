// The double-precision geometry of the Robust and Continuous exact tests (exact.h).
#include "psc/bullet/exact.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include "robust_kernel.h"

namespace psc::bullet {
namespace {

ClosestPoint closestOnSegment(const Vec3& p, const Vec3& a, const Vec3& b) {
  const Vec3 ab = b - a;
  const double len2 = ab.squaredNorm();
  const double t = len2 > 0.0 ? std::clamp((p - a).dot(ab) / len2, 0.0, 1.0) : 0.0;
  ClosestPoint r;
  r.distance2 = (p - (a + t * ab)).squaredNorm();
  r.weights = {1.0 - t, t, 0.0};
  return r;
}

double maxEdge2(const Vec3& a, const Vec3& b, const Vec3& c) {
  return std::max({(b - a).squaredNorm(), (c - b).squaredNorm(), (a - c).squaredNorm()});
}

}  // namespace

ClosestPoint closestPointOnTriangle(const Vec3& p, const Vec3& a, const Vec3& b, const Vec3& c) {
  using detail::robustV3;
  const detail::RobustV3<double> pp = robustV3(p), aa = robustV3(a), bb = robustV3(b), cc = robustV3(c);
  if (detail::robustDegenerate(aa, bb, cc)) {
    // Degenerate: the nearest of the three edges (a point-sized triangle gives a's distance).
    ClosestPoint best = closestOnSegment(p, a, b);
    ClosestPoint bc = closestOnSegment(p, b, c);
    if (bc.distance2 < best.distance2) best = {bc.distance2, {0.0, bc.weights[0], bc.weights[1]}};
    ClosestPoint ca = closestOnSegment(p, c, a);
    if (ca.distance2 < best.distance2) best = {ca.distance2, {ca.weights[1], 0.0, ca.weights[0]}};
    return best;
  }
  ClosestPoint r;
  detail::robustClosest(pp, aa, bb, cc, r.weights[0], r.weights[1], r.weights[2], r.distance2);
  return r;
}

namespace {

/// f(t) = c[0] + c[1] t + c[2] t² + c[3] t³
double cubic(const double c[4], double t) { return ((c[3] * t + c[2]) * t + c[1]) * t + c[0]; }

/// Roots in (0, 1) of c0 + c1 t + c2 t², ascending; appended to out.
void quadraticRootsInside(double c0, double c1, double c2, double* out, int& count) {
  double r[2];
  int n = 0;
  if (c2 == 0.0) {
    if (c1 != 0.0) r[n++] = -c0 / c1;
  } else {
    const double disc = c1 * c1 - 4.0 * c2 * c0;
    if (disc >= 0.0) {
      const double q = -0.5 * (c1 + std::copysign(std::sqrt(disc), c1));
      r[n++] = q / c2;
      if (q != 0.0) r[n++] = c0 / q;
    }
  }
  if (n == 2 && r[1] < r[0]) std::swap(r[0], r[1]);
  for (int i = 0; i < n; ++i)
    if (r[i] > 0.0 && r[i] < 1.0 && (count == 0 || r[i] > out[count - 1])) out[count++] = r[i];
}

/// The root of f in [lo, hi], where f is monotone with f(lo), f(hi) of opposite signs: Newton's
/// method kept inside the shrinking bracket (bisection when a step would leave it).
double rootInPiece(const double c[4], double lo, double hi, double flo, double fhi) {
  const bool rising = flo < 0.0;
  double t = lo + (hi - lo) * (flo / (flo - fhi));  // secant start
  if (!(t > lo && t < hi)) t = 0.5 * (lo + hi);
  for (int k = 0; k < 100; ++k) {
    const double ft = cubic(c, t);
    if (ft == 0.0) return t;
    if ((ft < 0.0) == rising) lo = t; else hi = t;
    const double slope = (3.0 * c[3] * t + 2.0 * c[2]) * t + c[1];
    double next = t - ft / slope;
    if (!(next > lo && next < hi)) next = 0.5 * (lo + hi);
    if (next <= lo || next >= hi || std::abs(next - t) <= 4.0 * std::numeric_limits<double>::epsilon()) return next;
    t = next;
  }
  return t;
}

}  // namespace

std::optional<Crossing> firstCrossing(const std::array<Vec3, 4>& start, const std::array<Vec3, 4>& end) {
  // Relative to the triangle's first vertex: f(t) = (e1(t) × e2(t)) · r(t), each linear in t, with
  // its coefficients, scale and rounding tolerance, and the tests that rule a crossing out, from
  // robust_kernel.h (which the exact stage's lanes run first, four pairs at a time).
  double c[4], scale = 0.0, tol = 0.0;
  using detail::robustV3;
  const bool ruled_out =
      detail::crossingRuledOut(robustV3(start[0]), robustV3(start[1]), robustV3(start[2]), robustV3(start[3]),
                               robustV3(end[0]), robustV3(end[1]), robustV3(end[2]), robustV3(end[3]), c, scale, tol);
  if (!(scale > 0.0) || !std::isfinite(scale)) return std::nullopt;
  // Rounding of f is a few ulps of L³ (tol); Bernstein coefficients on [0, 1] beyond ±tol on one
  // side mean no root, all within ±tol coplanar all step (never changes side); and the swept
  // triangle lies in the box of its six positions: a point whose segment's box misses it (by more
  // than the inside tolerance) cannot meet it.
  if (ruled_out) return std::nullopt;
  // Monotone pieces of f between 0, the roots of f' in (0, 1), and 1.
  double s[4] = {0.0};
  int count = 1;
  quadraticRootsInside(c[1], 2.0 * c[2], 3.0 * c[3], s, count);
  s[count++] = 1.0;
  double fs[4];
  for (int i = 0; i < count; ++i) fs[i] = cubic(c, s[i]);

  const auto meets = [&](double t) -> std::optional<Crossing> {
    const Vec3 p = start[0] + t * (end[0] - start[0]);
    const Vec3 a = start[1] + t * (end[1] - start[1]);
    const Vec3 bb = start[2] + t * (end[2] - start[2]);
    const Vec3 cc = start[3] + t * (end[3] - start[3]);
    const ClosestPoint cp = closestPointOnTriangle(p, a, bb, cc);
    double reach2 = maxEdge2(a, bb, cc);
    if (!(reach2 > 0.0)) reach2 = scale * scale;
    if (cp.distance2 > kCrossingTolerance * kCrossingTolerance * reach2) return std::nullopt;
    return Crossing{t, cp.weights};
  };
  // After the first crossing in piece i: the later sign changes through the triangle.
  const auto withReturns = [&](Crossing hit, int i) {
    for (int j = i + 1; j + 1 < count; ++j) {
      if (std::abs(fs[j]) <= tol || std::abs(fs[j + 1]) <= tol || (fs[j] > 0.0) == (fs[j + 1] > 0.0)) continue;
      hit.returns += meets(rootInPiece(c, s[j], s[j + 1], fs[j], fs[j + 1])).has_value() ? 1 : 0;
    }
    return hit;
  };
  for (int i = 0; i + 1 < count; ++i) {
    // A start in the plane (i = 0) has no side to leave: not a crossing.
    if (std::abs(fs[i]) <= tol) {
      if (i > 0)
        if (auto hit = meets(s[i])) return withReturns(*hit, i);
      continue;
    }
    if (std::abs(fs[i + 1]) <= tol || (fs[i] > 0.0) == (fs[i + 1] > 0.0)) continue;
    if (auto hit = meets(rootInPiece(c, s[i], s[i + 1], fs[i], fs[i + 1]))) return withReturns(*hit, i);
  }
  if (std::abs(fs[count - 1]) <= tol) return meets(1.0);
  return std::nullopt;
}

}  // namespace psc::bullet
