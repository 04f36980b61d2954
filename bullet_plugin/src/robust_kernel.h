// Private: the arithmetic of Robust's own contact (the exact closest point of a triangle, in
// double, and the contact's unit normal), written once for any "real" type R: plain double in
// exact_geometry.cpp and exact_stage.cpp, four AVX lanes of doubles in vf_lanes.cpp. Both see the
// same operations in the same order (no FMA: the build does not enable it), so a lane's result is
// the scalar one bit for bit; tests/bullet/exact_test.cpp (LanesAreBulletsTestBitForBit) checks it.
//
// Branches become selections: every region of the triangle (Ericson, Real-Time Collision
// Detection §5.1.5) gets its weights computed, and the first region whose condition holds, in
// Ericson's order, is kept. Divisions of the regions not kept may give infinities or NaNs; they are
// never selected.
//
// The ops R must have: + − * / between Rs, R(double) constants, sqrt(R), and the mask type
// M = decltype(R < R) with le, ge, lt, gt, both(M, M) and select(M, R if_true, R if_false).
//
// Everything here has internal linkage: each including file compiles its own copy (vf_lanes.cpp
// with AVX enabled for it), so no instantiation is shared between files built with different
// instruction sets.
#pragma once

#include <cmath>

namespace psc::bullet::detail {
namespace {

// The scalar forms of the operations (before the templates: for double, a template's calls find
// only what is declared where it is defined).
inline bool le(double a, double b) { return a <= b; }
inline bool ge(double a, double b) { return a >= b; }
inline bool gt(double a, double b) { return a > b; }
inline bool notGreater(double a, double b) { return !(a > b); }
inline bool both(bool a, bool b) { return a && b; }
inline double select(bool m, double if_true, double if_false) { return m ? if_true : if_false; }
using std::sqrt;

/// A triangle is reduced to its edges when |ab × ac|² ≤ this × (longest edge²)², i.e. its height
/// is below 1e-12 of its longest edge: the same rule as the demo's ground truth.
constexpr double kDegenerateRelative = 1e-24;

template <class R>
struct RobustV3 {
  R x, y, z;
};

template <class R>
[[gnu::always_inline]] inline RobustV3<R> minus(const RobustV3<R>& a, const RobustV3<R>& b) {
  return {a.x - b.x, a.y - b.y, a.z - b.z};
}
/// (x·x' + y·y') + z·z'
template <class R>
[[gnu::always_inline]] inline R dot3(const RobustV3<R>& a, const RobustV3<R>& b) {
  return (a.x * b.x + a.y * b.y) + a.z * b.z;
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
  wa = select(on_bc, zero, wa);  // edge BC
  wb = select(on_bc, one - t, wb);
  wc = select(on_bc, t, wc);
  wa = select(on_ac, one - t, wa);  // edge AC
  wb = select(on_ac, zero, wb);
  wc = select(on_ac, t, wc);
  wa = select(at_c, zero, wa);  // corner C
  wb = select(at_c, zero, wb);
  wc = select(at_c, one, wc);
  wa = select(on_ab, one - t, wa);  // edge AB
  wb = select(on_ab, t, wb);
  wc = select(on_ab, zero, wc);
  wa = select(at_b, zero, wa);  // corner B
  wb = select(at_b, one, wb);
  wc = select(at_b, zero, wc);
  wa = select(at_a, one, wa);  // corner A
  wb = select(at_a, zero, wb);
  wc = select(at_a, zero, wc);
  const RobustV3<R> q{(a.x * wa + b.x * wb) + c.x * wc, (a.y * wa + b.y * wb) + c.y * wc,
                      (a.z * wa + b.z * wb) + c.z * wc};
  const RobustV3<R> d = minus(p, q);
  distance2 = dot3(d, d);
}

/// Whether the triangle is reduced to its edges (kDegenerateRelative).
template <class R>
[[gnu::always_inline]] inline auto robustDegenerate(const RobustV3<R>& a, const RobustV3<R>& b,
                                                    const RobustV3<R>& c) {
  const RobustV3<R> ab = minus(b, a), ac = minus(c, a), bc = minus(c, b), ca = minus(a, c);
  const RobustV3<R> n{ab.y * ac.z - ab.z * ac.y, ab.z * ac.x - ab.x * ac.z, ab.x * ac.y - ab.y * ac.x};
  const R n2 = dot3(n, n);
  const R l_ab = dot3(ab, ab), l_bc = dot3(bc, bc), l_ca = dot3(ca, ca);
  const R l2 = select(gt(l_bc, l_ab), l_bc, l_ab);
  const R longest = select(gt(l_ca, l2), l_ca, l2);
  return notGreater(n2, R(kDegenerateRelative) * longest * longest);
}

/// The contact's direction: p minus the face point at weights (wa, wb, wc), evaluated as the face
/// point is, from zero, corner by corner; its length, and the unit normal away · (1 / length). `short`
/// holds where the length is at most 1e-9 of the radius: there the normal is the caller's to find.
template <class R>
[[gnu::always_inline]] inline auto robustNormal(const RobustV3<R>& p, const RobustV3<R>& a, const RobustV3<R>& b,
                                                const RobustV3<R>& c, R wa, R wb, R wc, R radius,
                                                RobustV3<R>& normal) {
  const R zero(0.0);
  const RobustV3<R> f{((zero + wa * a.x) + wb * b.x) + wc * c.x, ((zero + wa * a.y) + wb * b.y) + wc * c.y,
                      ((zero + wa * a.z) + wb * b.z) + wc * c.z};
  const RobustV3<R> away = minus(p, f);
  const R length = sqrt(dot3(away, away));
  const R inverse = R(1.0) / length;
  normal = {away.x * inverse, away.y * inverse, away.z * inverse};
  return notGreater(length, R(1e-9) * radius);
}

}  // namespace
}  // namespace psc::bullet::detail
