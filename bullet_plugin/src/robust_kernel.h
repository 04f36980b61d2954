// Private: the arithmetic of Robust's own contact (the closest point of a triangle and the
// contact's unit normal) and the first part of Continuous's crossing test (crossingRuledOut),
// written once for any "real" type R: plain float and double in exact_stage.cpp and
// exact_geometry.cpp, eight AVX lanes of floats and four of doubles in vf_lanes.cpp. A lane and its
// scalar form see the same operations in the same order (no FMA: the build does not enable it), so
// a lane's result is the scalar one bit for bit; tests/bullet/exact_test.cpp
// (LanesAreBulletsTestBitForBit) checks it.
//
// Robust's contact is first computed in single precision, from Bullet's float positions taken
// relative to the node (the corners minus the node, p = 0: exact for a corner within a factor of
// two of the node's coordinates, as Bullet's own test takes them), so every quantity is a
// difference of nearby positions or a product of such differences and its rounding is relative to
// the triangle and the distance, not to where they are (a small triangle far from the origin keeps
// its relative precision). Where single precision cannot hold that (a sliver, a triangle below 1e-6
// or above 1e6 in size, a node within a hundredth of the radius of the face), robustNeedsDouble or
// robustNormal's `short` sends the pair to the double path: the exact closest point
// (closestPointOnTriangle).
//
// Branches become selections: every region of the triangle (Ericson, Real-Time Collision
// Detection §5.1.5) gets its weights computed, and the first region whose condition holds, in
// Ericson's order, is kept. Divisions of the regions not kept may give infinities or NaNs; they are
// never selected.
//
// The ops R must have: + − * / between Rs, R(double) constants, sqrt(R), and a mask type M
// returned by le, ge, lt, gt and notGreater(R, R), with both(M, M), either(M, M) and
// select(M, R if_true, R if_false).
//
// Everything here has internal linkage: each including file compiles its own copy (vf_lanes.cpp
// with AVX enabled for it), so no instantiation is shared between files built with different
// instruction sets.
#pragma once

#include "psc/bullet/exact.h"

#include <cmath>
#include <limits>
#include <type_traits>

namespace psc::bullet::detail {
namespace {

// The scalar forms of the operations, for float (robustContact's first path, with no promotion
// to double) and double (before the templates: for those, a template's calls find only what is
// declared where it is defined).
template <class T>
using Scalar = std::enable_if_t<std::is_floating_point_v<T>, T>;
template <class T>
inline bool le(T a, Scalar<T> b) { return a <= b; }
template <class T>
inline bool ge(T a, Scalar<T> b) { return a >= b; }
template <class T>
inline bool gt(T a, Scalar<T> b) { return a > b; }
template <class T>
inline bool notGreater(T a, Scalar<T> b) { return !(a > b); }
template <class T>
inline bool lt(T a, Scalar<T> b) { return a < b; }
inline bool both(bool a, bool b) { return a && b; }
inline bool either(bool a, bool b) { return a || b; }
template <class T>
inline T select(bool m, T if_true, Scalar<T> if_false) { return m ? if_true : if_false; }
using std::sqrt;

/// A triangle is reduced to its edges when |ab × ac|² ≤ this × (longest edge²)², i.e. its height
/// is below 1e-12 of its longest edge: the same rule as the demo's ground truth.
constexpr double kDegenerateRelative = 1e-24;

/// Single precision leaves a triangle to the double path when |ab × ac|² ≤ this × (longest edge²)²,
/// i.e. its height is below about 3% of its longest edge: the region weights' rounding grows as
/// (longest / height)², about 2.4e-4 of the triangle at this bound, far inside the ground truth's
/// band.
constexpr double kSingleThin = 1e-3;
/// ... and when its longest edge² lies outside [this, 1 / this]: the fourth powers above stay
/// within float's normal range.
constexpr double kSingleSmallest2 = 1e-12;
/// A node nearer its closest point than this fraction of the radius has its normal from the double
/// path in single precision (in double: robustNormal's kDoubleShort): the face point's rounding,
/// relative to the coordinates, would turn the direction.
constexpr double kSingleShort = 1e-2;
constexpr double kDoubleShort = 1e-9;
/// ... and so does a node nearer than this times the face point's own rounding, which grows with
/// the face, not the radius: about 2 ε L (L / h)² for a face of longest edge L and height h (ε the
/// precision's unit roundoff; at most 2.4e-4 L in single precision, kSingleThin). A hundred times
/// that keeps the direction within a hundredth of a radian when the radius is far below the face
/// (a review's finding, stop 46: 47° off at a radius of 1e-4 of the face). The double path's own
/// short pairs get the face's normal (normalWithoutDistance).
constexpr double kSingleFaceShort = 100.0 * 2.0 * 1.1920928955078125e-07;
constexpr double kDoubleFaceShort = 100.0 * 2.0 * 2.220446049250313e-16;

template <class R>
struct RobustV3 {
  R x, y, z;
};

/// Any vector with x(), y(), z() (Eigen's, Bullet's) in double.
template <class V>
inline RobustV3<double> robustV3(const V& v) {
  return {double(v.x()), double(v.y()), double(v.z())};
}

template <class R>
[[gnu::always_inline]] inline RobustV3<R> minus(const RobustV3<R>& a, const RobustV3<R>& b) {
  return {a.x - b.x, a.y - b.y, a.z - b.z};
}
/// (x·x' + y·y') + z·z'
template <class R>
[[gnu::always_inline]] inline R dot3(const RobustV3<R>& a, const RobustV3<R>& b) {
  return (a.x * b.x + a.y * b.y) + a.z * b.z;
}

/// (wa, wb, wc) = (a, b, c) where m holds.
template <class M, class R>
[[gnu::always_inline]] inline void weightsWhere(M m, R a, R b, R c, R& wa, R& wb, R& wc) {
  wa = select(m, a, wa);
  wb = select(m, b, wb);
  wc = select(m, c, wc);
}

/// The closest point of the triangle (a, b, c) to p, for a triangle that is not degenerate
/// (robustDegenerate false): its weights and squared distance.
template <class R>
[[gnu::always_inline]] inline void robustClosest(const RobustV3<R>& p, const RobustV3<R>& a, const RobustV3<R>& b,
                                                 const RobustV3<R>& c, R& wa, R& wb, R& wc, R& distance2) {
  const R zero(0.0), one(1.0);
  const RobustV3<R> ab = minus(b, a), ac = minus(c, a);
  const RobustV3<R> ap = minus(p, a), bp = minus(p, b), cp = minus(p, c);
  const R d1 = dot3(ab, ap), d2 = dot3(ac, ap);
  const R d3 = dot3(ab, bp), d4 = dot3(ac, bp);
  const R d5 = dot3(ab, cp), d6 = dot3(ac, cp);
  const R vc = d1 * d4 - d3 * d2;
  const R vb = d5 * d2 - d1 * d6;
  const R va = d3 * d6 - d5 * d4;
  // Each region's weights need at most one division, num / den: the face's inside (1 over the
  // sum, then three products), or the fraction t along the edge of an edge region. The lane's own
  // pair is picked first, in Ericson's order of the edges (AB before AC before BC; a corner or the
  // inside below overrides them as Ericson's earlier returns do), so one division serves every
  // region, with the same operands, and the same result, as a division per region.
  const R e43 = d4 - d3, e56 = d5 - d6;
  const auto on_bc = both(both(le(va, zero), ge(e43, zero)), ge(e56, zero));
  const auto on_ac = both(both(le(vb, zero), ge(d2, zero)), le(d6, zero));
  const auto on_ab = both(both(le(vc, zero), ge(d1, zero)), le(d3, zero));
  const auto at_c = both(ge(d6, zero), le(d5, d6));
  const auto at_b = both(ge(d3, zero), le(d4, d3));
  const auto at_a = both(le(d1, zero), le(d2, zero));
  R num = select(on_bc, e43, one), den = select(on_bc, e43 + e56, (va + vb) + vc);
  num = select(on_ac, d2, num);
  den = select(on_ac, d2 - d6, den);
  num = select(on_ab, d1, num);
  den = select(on_ab, d1 - d3, den);
  const R t = num / den;
  // Inside the face.
  wa = va * t;
  wb = vb * t;
  wc = vc * t;
  // Then each region from the last in Ericson's order to the first, each overriding the later ones.
  const R u = one - t;
  weightsWhere(on_bc, zero, u, t, wa, wb, wc);        // edge BC
  weightsWhere(on_ac, u, zero, t, wa, wb, wc);        // edge AC
  weightsWhere(at_c, zero, zero, one, wa, wb, wc);    // corner C
  weightsWhere(on_ab, u, t, zero, wa, wb, wc);        // edge AB
  weightsWhere(at_b, zero, one, zero, wa, wb, wc);    // corner B
  weightsWhere(at_a, one, zero, zero, wa, wb, wc);    // corner A
  const RobustV3<R> q{(a.x * wa + b.x * wb) + c.x * wc, (a.y * wa + b.y * wb) + c.y * wc,
                      (a.z * wa + b.z * wb) + c.z * wc};
  const RobustV3<R> d = minus(p, q);
  distance2 = dot3(d, d);
}

/// |ab × ac|² and the longest edge² of the triangle (a, b, c).
template <class R>
[[gnu::always_inline]] inline void robustShape(const RobustV3<R>& a, const RobustV3<R>& b, const RobustV3<R>& c,
                                               R& n2, R& longest2) {
  const RobustV3<R> ab = minus(b, a), ac = minus(c, a), bc = minus(c, b), ca = minus(a, c);
  const RobustV3<R> n{ab.y * ac.z - ab.z * ac.y, ab.z * ac.x - ab.x * ac.z, ab.x * ac.y - ab.y * ac.x};
  n2 = dot3(n, n);
  const R l_ab = dot3(ab, ab), l_bc = dot3(bc, bc), l_ca = dot3(ca, ca);
  const R l2 = select(gt(l_bc, l_ab), l_bc, l_ab);
  longest2 = select(gt(l_ca, l2), l_ca, l2);
}

/// Whether the triangle is reduced to its edges (kDegenerateRelative).
template <class R>
[[gnu::always_inline]] inline auto robustDegenerate(const RobustV3<R>& a, const RobustV3<R>& b,
                                                    const RobustV3<R>& c) {
  R n2, longest;
  robustShape(a, b, c, n2, longest);
  return notGreater(n2, R(kDegenerateRelative) * longest * longest);
}

/// Whether the single-precision path leaves the triangle to the double one (kSingleThin,
/// kSingleSmallest2); a NaN in a corner leaves it too.
template <class R>
[[gnu::always_inline]] inline auto robustNeedsDouble(const RobustV3<R>& a, const RobustV3<R>& b,
                                                     const RobustV3<R>& c) {
  R n2, longest;
  robustShape(a, b, c, n2, longest);
  // notGreater holds for a NaN (a NaN corner makes n2 one).
  return either(either(notGreater(n2, R(kSingleThin) * longest * longest), notGreater(longest, R(kSingleSmallest2))),
                gt(longest, R(1.0 / kSingleSmallest2)));
}

/// The contact's direction: p minus the face point at weights (wa, wb, wc), evaluated as the face
/// point is, from zero, corner by corner; its length, and the unit normal away · (1 / length). `short`
/// holds where the length is at most `short_fraction` of the radius (kSingleShort, kDoubleShort) or
/// at most `face_fraction` (kSingleFaceShort, kDoubleFaceShort) times L · (L / h)² for a point
/// inside the face (L · 1 on an edge or a corner), L² = the longest edge², (L h)² ≈ |ab × ac|²:
/// there the normal is the caller's to find (inside the face, the face's normal is the direction).
template <class R>
[[gnu::always_inline]] inline auto robustNormal(const RobustV3<R>& p, const RobustV3<R>& a, const RobustV3<R>& b,
                                                const RobustV3<R>& c, R wa, R wb, R wc, R radius, R short_fraction,
                                                R face_fraction, RobustV3<R>& normal) {
  const R zero(0.0);
  const RobustV3<R> f{((zero + wa * a.x) + wb * b.x) + wc * c.x, ((zero + wa * a.y) + wb * b.y) + wc * c.y,
                      ((zero + wa * a.z) + wb * b.z) + wc * c.z};
  const RobustV3<R> away = minus(p, f);
  const R length2 = dot3(away, away);
  const R length = sqrt(length2);
  const R inverse = R(1.0) / length;
  normal = {away.x * inverse, away.y * inverse, away.z * inverse};
  // The inside's weights come from products of the corners' differences, whose rounding (L / h)²
  // amplifies; an edge's or a corner's only from one division along the edge.
  R n2, longest2;
  robustShape(a, b, c, n2, longest2);
  const auto inside = both(both(gt(wa, zero), gt(wb, zero)), gt(wc, zero));
  const R amplified = select(inside, longest2 * longest2 / n2, R(1.0));
  const R face_short = face_fraction * amplified;
  return either(notGreater(length, short_fraction * radius), notGreater(length2, (face_short * face_short) * longest2));
}

template <class R>
[[gnu::always_inline]] inline RobustV3<R> cross3(const RobustV3<R>& a, const RobustV3<R>& b) {
  return {a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x};
}
template <class R>
[[gnu::always_inline]] inline RobustV3<R> plus(const RobustV3<R>& a, const RobustV3<R>& b) {
  return {a.x + b.x, a.y + b.y, a.z + b.z};
}
template <class R>
[[gnu::always_inline]] inline R larger(R a, R b) {
  return select(gt(b, a), b, a);
}
template <class R>
[[gnu::always_inline]] inline R smaller(R a, R b) {
  return select(lt(b, a), b, a);
}

/// The start of firstCrossing (exact_geometry.cpp): a point moving from p0 to p1 against a
/// triangle moving from (a0, b0, c0) to (a1, b1, c1), each linear over the step. f(t) = (e1(t) ×
/// e2(t)) · r(t), relative to the first corner, is the cubic c[0] + c[1] t + c[2] t² + c[3] t³;
/// `scale` is the longest of the six relative vectors and `tol` the rounding of f. Returns where
/// the point cannot cross: f keeps one sign beyond ±tol over [0, 1] by its Bernstein bound, or stays
/// within ±tol (coplanar for the whole step), or the point's path box misses the box of the
/// triangle's six positions by more than the inside tolerance. Where it returns false, scale may
/// be 0 or not finite: firstCrossing checks that first.
template <class R>
[[gnu::always_inline]] inline auto crossingRuledOut(const RobustV3<R>& p0, const RobustV3<R>& a0, const RobustV3<R>& b0,
                                                    const RobustV3<R>& c0, const RobustV3<R>& p1, const RobustV3<R>& a1,
                                                    const RobustV3<R>& b1, const RobustV3<R>& c1, R c[4], R& scale,
                                                    R& tol) {
  const RobustV3<R> e1_0 = minus(b0, a0), e2_0 = minus(c0, a0), r_0 = minus(p0, a0);
  const RobustV3<R> e1_1 = minus(b1, a1), e2_1 = minus(c1, a1), r_1 = minus(p1, a1);
  const RobustV3<R> de1 = minus(e1_1, e1_0), de2 = minus(e2_1, e2_0), dr = minus(r_1, r_0);
  const RobustV3<R> n0 = cross3(e1_0, e2_0);
  const RobustV3<R> n1 = plus(cross3(e1_0, de2), cross3(de1, e2_0));
  const RobustV3<R> n2 = cross3(de1, de2);
  c[0] = dot3(n0, r_0);
  c[1] = dot3(n0, dr) + dot3(n1, r_0);
  c[2] = dot3(n1, dr) + dot3(n2, r_0);
  c[3] = dot3(n2, dr);
  const R longest = larger(larger(larger(dot3(e1_0, e1_0), dot3(e2_0, e2_0)), larger(dot3(r_0, r_0), dot3(e1_1, e1_1))),
                           larger(dot3(e2_1, e2_1), dot3(r_1, r_1)));
  scale = sqrt(longest);
  tol = R(64.0 * std::numeric_limits<double>::epsilon()) * scale * scale * scale;
  const R three(3.0), two(2.0);
  const R bern0 = c[0], bern1 = c[0] + c[1] / three, bern2 = c[0] + (two * c[1] + c[2]) / three,
          bern3 = ((c[0] + c[1]) + c[2]) + c[3];
  const R bmin = smaller(smaller(bern0, bern1), smaller(bern2, bern3));
  const R bmax = larger(larger(bern0, bern1), larger(bern2, bern3));
  const R minus_tol = R(0.0) - tol;
  auto out = either(gt(bmin, tol), lt(bmax, minus_tol));
  out = either(out, both(ge(bmin, minus_tol), le(bmax, tol)));
  // The boxes, with the same slack as firstCrossing's inside test.
  const R lo_x = smaller(smaller(smaller(a0.x, b0.x), smaller(c0.x, a1.x)), smaller(b1.x, c1.x));
  const R lo_y = smaller(smaller(smaller(a0.y, b0.y), smaller(c0.y, a1.y)), smaller(b1.y, c1.y));
  const R lo_z = smaller(smaller(smaller(a0.z, b0.z), smaller(c0.z, a1.z)), smaller(b1.z, c1.z));
  const R hi_x = larger(larger(larger(a0.x, b0.x), larger(c0.x, a1.x)), larger(b1.x, c1.x));
  const R hi_y = larger(larger(larger(a0.y, b0.y), larger(c0.y, a1.y)), larger(b1.y, c1.y));
  const R hi_z = larger(larger(larger(a0.z, b0.z), larger(c0.z, a1.z)), larger(b1.z, c1.z));
  const R slack = R(2.0 * kCrossingTolerance) * larger(larger(hi_x - lo_x, hi_y - lo_y), hi_z - lo_z);
  const R plo_x = smaller(p0.x, p1.x), plo_y = smaller(p0.y, p1.y), plo_z = smaller(p0.z, p1.z);
  const R phi_x = larger(p0.x, p1.x), phi_y = larger(p0.y, p1.y), phi_z = larger(p0.z, p1.z);
  out = either(out, either(either(gt(plo_x - hi_x, slack), gt(plo_y - hi_y, slack)), gt(plo_z - hi_z, slack)));
  out = either(out, either(either(gt(lo_x - phi_x, slack), gt(lo_y - phi_y, slack)), gt(lo_z - phi_z, slack)));
  return out;
}

}  // namespace
}  // namespace psc::bullet::detail
