#include "vf_lanes.h"

#include <atomic>
#include <cfloat>
#include <cmath>
#include <limits>

// Before the AVX region below: robust_kernel.h includes it, and no header outside this file may be
// compiled for AVX here (its inline functions could then be the copy another file links to).
#include "psc/bullet/exact.h"

#if defined(__x86_64__) && defined(__GNUC__)
#include <immintrin.h>
#define PSC_HAVE_VF_LANES 1
#endif

namespace psc::bullet::detail {
namespace {

std::atomic<bool> g_allowed{true};

#if defined(PSC_HAVE_VF_LANES)
// AVX only: no FMA may be formed (Bullet's scalar code rounds every product).
#define PSC_AVX [[gnu::target("avx"), gnu::always_inline]] inline

struct V3 {
  __m256 x, y, z;
};

PSC_AVX __m256 add(__m256 a, __m256 b) { return _mm256_add_ps(a, b); }
PSC_AVX __m256 sub(__m256 a, __m256 b) { return _mm256_sub_ps(a, b); }
PSC_AVX __m256 mul(__m256 a, __m256 b) { return _mm256_mul_ps(a, b); }
PSC_AVX __m256 div(__m256 a, __m256 b) { return _mm256_div_ps(a, b); }
PSC_AVX __m256 gt(__m256 a, __m256 b) { return _mm256_cmp_ps(a, b, _CMP_GT_OQ); }
PSC_AVX __m256 lt(__m256 a, __m256 b) { return _mm256_cmp_ps(a, b, _CMP_LT_OQ); }
PSC_AVX __m256 notGt(__m256 a, __m256 b) { return _mm256_cmp_ps(a, b, _CMP_NGT_UQ); }  // !(a > b)
PSC_AVX __m256 le(__m256 a, __m256 b) { return _mm256_cmp_ps(a, b, _CMP_LE_OQ); }
PSC_AVX __m256 both(__m256 a, __m256 b) { return _mm256_and_ps(a, b); }
PSC_AVX __m256 either(__m256 a, __m256 b) { return _mm256_or_ps(a, b); }
PSC_AVX __m256 butNot(__m256 a, __m256 not_b) { return _mm256_andnot_ps(not_b, a); }  // a && !not_b
PSC_AVX __m256 negate(__m256 a) { return _mm256_xor_ps(a, _mm256_set1_ps(-0.0f)); }  // exact, like unary minus
// Masks are whole lanes (compares and their and/or): and, andnot and or select exactly as blendv
// would. GCC 12 folds _mm256_blendv_ps into a vector condition on the mask's sign bits, which
// AVX (no 256-bit integer compare) cannot expand: it became eight scalar branches per select.
PSC_AVX __m256 pick(__m256 keep, __m256 take, __m256 mask) {
  return _mm256_or_ps(_mm256_and_ps(mask, take), _mm256_andnot_ps(mask, keep));
}

PSC_AVX V3 load(const float* x, const float* y, const float* z) {
  return {_mm256_load_ps(x), _mm256_load_ps(y), _mm256_load_ps(z)};
}
PSC_AVX V3 sub(const V3& a, const V3& b) { return {sub(a.x, b.x), sub(a.y, b.y), sub(a.z, b.z)}; }
PSC_AVX V3 add(const V3& a, const V3& b) { return {add(a.x, b.x), add(a.y, b.y), add(a.z, b.z)}; }
PSC_AVX V3 scale(const V3& a, __m256 s) { return {mul(a.x, s), mul(a.y, s), mul(a.z, s)}; }
/// btVector3::dot: (x·x' + y·y') + z·z'.
PSC_AVX __m256 dot(const V3& a, const V3& b) { return add(add(mul(a.x, b.x), mul(a.y, b.y)), mul(a.z, b.z)); }
/// btVector3::cross, component by component as Bullet writes it.
PSC_AVX V3 cross(const V3& a, const V3& b) {
  return {sub(mul(a.y, b.z), mul(a.z, b.y)), sub(mul(a.z, b.x), mul(a.x, b.z)), sub(mul(a.x, b.y), mul(a.y, b.x))};
}
PSC_AVX V3 pick(const V3& keep, const V3& take, __m256 mask) {
  return {pick(keep.x, take.x, mask), pick(keep.y, take.y, mask), pick(keep.z, take.z, mask)};
}

/// The edge ProjectOrigin(a, b, prj, sqd) of btSoftBodyInternals.h in the lanes of `active`;
/// `skipped` gains the active lanes whose edge Bullet's threshold skips.
PSC_AVX void projectEdge(const V3& a, const V3& b, __m256 active, V3& prj, __m256& sqd, __m256& skipped) {
  const __m256 eps = _mm256_set1_ps(FLT_EPSILON);
  const V3 d = sub(b, a);
  const __m256 m2 = dot(d, d);
  const __m256 long_enough = gt(m2, eps);
  skipped = either(skipped, butNot(active, long_enough));
  const __m256 x = div(negate(dot(a, d)), m2);
  // Clamp(x, 0, 1) = x < 0 ? 0 : x > 1 ? 1 : x
  const __m256 t = pick(pick(x, _mm256_set1_ps(1.0f), gt(x, _mm256_set1_ps(1.0f))), _mm256_setzero_ps(),
                        lt(x, _mm256_setzero_ps()));
  const V3 p = add(a, scale(d, t));
  const __m256 l2 = dot(p, p);
  const __m256 take = both(both(active, long_enough), lt(l2, sqd));
  prj = pick(prj, p, take);
  sqd = pick(sqd, l2, take);
}

/// fillContact's masses and constraint mixing at weights w: mb = BaryEval(corner m_im, w), 0 when
/// a corner is fixed; cfm0 = ma / (ma + mb) · kshr0 and cfm1 = mb / (ma + mb) · kshr1 stored.
/// Returns the lanes where a side can move (ma + mb > 0), which a contact needs.
PSC_AVX __m256 contactMixing(const VfLanesIn& in, __m256 wx, __m256 wy, __m256 wz, float kshr0, float kshr1,
                             float* cfm0, float* cfm1) {
  const __m256 zero = _mm256_setzero_ps();
  const __m256 ma = _mm256_load_ps(in.im);
  const __m256 ia = _mm256_load_ps(in.ia), ib = _mm256_load_ps(in.ib), ic = _mm256_load_ps(in.ic);
  const __m256 fixed = either(le(ia, zero), either(le(ib, zero), le(ic, zero)));
  const __m256 mb = pick(add(add(mul(ia, wx), mul(ib, wy)), mul(ic, wz)), zero, fixed);
  const __m256 ms = add(ma, mb);
  _mm256_store_ps(cfm0, mul(div(ma, ms), _mm256_set1_ps(kshr0)));
  _mm256_store_ps(cfm1, mul(div(mb, ms), _mm256_set1_ps(kshr1)));
  return gt(ms, zero);
}

[[gnu::target("avx")]] void lanesAvx(const VfLanesIn& in, float mrg, float kshr0, float kshr1, bool robust,
                                     bool motion_term, VfLanesOut& out) {
  const __m256 zero = _mm256_setzero_ps();
  const __m256 one = _mm256_set1_ps(1.0f);
  const __m256 flt_max = _mm256_set1_ps(FLT_MAX);  // SIMD_INFINITY
  const V3 o = load(in.ox, in.oy, in.oz);
  const V3 A = load(in.ax, in.ay, in.az), B = load(in.bx, in.by, in.bz), C = load(in.cx, in.cy, in.cz);

  // ProjectOrigin(A − o, B − o, C − o, p, d), the face version.
  const V3 a = sub(A, o), b = sub(B, o), c = sub(C, o);
  V3 p{zero, zero, zero};
  __m256 d = flt_max;
  const V3 q = cross(sub(b, a), sub(c, a));
  const __m256 m2 = dot(q, q);
  const __m256 valid = gt(m2, _mm256_set1_ps(FLT_EPSILON));
  __m256 skipped = notGt(m2, _mm256_set1_ps(FLT_EPSILON));
  const V3 n = scale(q, div(one, _mm256_sqrt_ps(m2)));  // q / btSqrt(m2) = q * (1 / btSqrt(m2))
  const __m256 k = dot(a, n);
  const __m256 k2 = mul(k, k);
  const __m256 take = both(valid, lt(k2, d));
  const V3 pf = scale(n, k);
  const __m256 in_ab = gt(dot(cross(sub(a, pf), sub(b, pf)), q), zero);
  const __m256 in_bc = gt(dot(cross(sub(b, pf), sub(c, pf)), q), zero);
  const __m256 in_ca = gt(dot(cross(sub(c, pf), sub(a, pf)), q), zero);
  const __m256 inside = both(take, both(in_ab, both(in_bc, in_ca)));
  p = pick(p, pf, inside);
  d = pick(d, k2, inside);
  const __m256 edges = butNot(take, inside);
  projectEdge(a, b, edges, p, d, skipped);
  projectEdge(b, c, edges, p, d, skipped);
  projectEdge(c, a, edges, p, d, skipped);
  // Every value ProjectOrigin assigns to d is below SIMD_INFINITY: d < FLT_MAX <=> p was set.
  const __m256 set = lt(d, flt_max);

  // m = mrg + (o − m_q).length() * 2 (or mrg alone); the pair is accepted when d < m·m.
  const V3 motion = sub(o, load(in.qx, in.qy, in.qz));
  const __m256 m = motion_term ? add(_mm256_set1_ps(mrg), mul(_mm256_sqrt_ps(dot(motion, motion)), _mm256_set1_ps(2.0f)))
                               : _mm256_set1_ps(mrg);
  const __m256 accept = lt(d, mul(m, m));

  // BaryCoord(A, B, C, p + o).
  const V3 P = add(p, o);
  const V3 aP = sub(A, P), bP = sub(B, P), cP = sub(C, P);
  const V3 c0 = cross(aP, bP), c1 = cross(bP, cP), c2 = cross(cP, aP);
  const __m256 w0 = _mm256_sqrt_ps(dot(c0, c0));
  const __m256 w1 = _mm256_sqrt_ps(dot(c1, c1));
  const __m256 w2 = _mm256_sqrt_ps(dot(c2, c2));
  const __m256 isum = div(one, add(add(w0, w1), w2));
  const __m256 wx = mul(w1, isum), wy = mul(w2, isum), wz = mul(w0, isum);

  const __m256 moves = contactMixing(in, wx, wy, wz, kshr0, kshr1, out.cfm0, out.cfm1);

  // c.m_normal = p / −btSqrt(d) = p * (1 / −btSqrt(d)).
  const V3 normal = scale(p, div(one, negate(_mm256_sqrt_ps(d))));
  _mm256_store_ps(out.nx, normal.x);
  _mm256_store_ps(out.ny, normal.y);
  _mm256_store_ps(out.nz, normal.z);
  _mm256_store_ps(out.wx, wx);
  _mm256_store_ps(out.wy, wy);
  _mm256_store_ps(out.wz, wz);
  _mm256_store_ps(out.margin, m);

  const __m256 scalar = butNot(accept, set);
  out.scalar = static_cast<std::uint32_t>(_mm256_movemask_ps(scalar));
  out.robust = 0;
  if (robust) {
    // discreteTest(robust): Bullet's contact only where accepted at d > 0; an accepted node on the
    // face, or a pair beyond the radius on a face or edge Bullet skipped, is Robust's own.
    out.robust = static_cast<std::uint32_t>(
                     _mm256_movemask_ps(either(both(accept, notGt(d, zero)), butNot(skipped, accept)))) &
                 ~out.scalar;
  }
  out.contact = static_cast<std::uint32_t>(_mm256_movemask_ps(both(both(accept, set), moves))) &
                ~(out.scalar | out.robust);
}
#endif

}  // namespace
}  // namespace psc::bullet::detail

#if defined(PSC_HAVE_VF_LANES)
// robust_kernel.h's templates over eight lanes of floats and four of doubles. Everything they call
// must be compiled for AVX, the templates included: so the header is read with AVX as this
// region's target (GCC's pragma; clang's attribute region does the same).
#if defined(__clang__)
#pragma clang attribute push(__attribute__((target("avx"))), apply_to = function)
#else
#pragma GCC push_options
#pragma GCC target("avx")
#endif
namespace psc::bullet::detail {
namespace {

struct D4 {
  __m256d v;
  D4() = default;
  PSC_AVX D4(__m256d x) : v(x) {}               // NOLINT(google-explicit-constructor)
  PSC_AVX D4(double x) : v(_mm256_set1_pd(x)) {}  // NOLINT(google-explicit-constructor)
};
struct M4 {
  __m256d m;
};
PSC_AVX D4 operator+(D4 a, D4 b) { return _mm256_add_pd(a.v, b.v); }
PSC_AVX D4 operator-(D4 a, D4 b) { return _mm256_sub_pd(a.v, b.v); }
PSC_AVX D4 operator*(D4 a, D4 b) { return _mm256_mul_pd(a.v, b.v); }
PSC_AVX D4 operator/(D4 a, D4 b) { return _mm256_div_pd(a.v, b.v); }
PSC_AVX D4 sqrt(D4 a) { return _mm256_sqrt_pd(a.v); }
PSC_AVX M4 le(D4 a, D4 b) { return {_mm256_cmp_pd(a.v, b.v, _CMP_LE_OQ)}; }
PSC_AVX M4 ge(D4 a, D4 b) { return {_mm256_cmp_pd(a.v, b.v, _CMP_GE_OQ)}; }
PSC_AVX M4 gt(D4 a, D4 b) { return {_mm256_cmp_pd(a.v, b.v, _CMP_GT_OQ)}; }
PSC_AVX M4 lt(D4 a, D4 b) { return {_mm256_cmp_pd(a.v, b.v, _CMP_LT_OQ)}; }
PSC_AVX M4 notGreater(D4 a, D4 b) { return {_mm256_cmp_pd(a.v, b.v, _CMP_NGT_UQ)}; }  // !(a > b)
PSC_AVX M4 both(M4 a, M4 b) { return {_mm256_and_pd(a.m, b.m)}; }
PSC_AVX M4 either(M4 a, M4 b) { return {_mm256_or_pd(a.m, b.m)}; }
PSC_AVX D4 select(M4 m, D4 if_true, D4 if_false) {  // as pick above: no blendv
  return _mm256_or_pd(_mm256_and_pd(m.m, if_true.v), _mm256_andnot_pd(m.m, if_false.v));
}

/// Eight lanes of floats, the same operations as D4 (Robust's single-precision contact).
struct F8 {
  __m256 v;
  F8() = default;
  PSC_AVX F8(__m256 x) : v(x) {}                                        // NOLINT(google-explicit-constructor)
  PSC_AVX F8(double x) : v(_mm256_set1_ps(static_cast<float>(x))) {}  // NOLINT(google-explicit-constructor)
};
struct M8 {
  __m256 m;
};
PSC_AVX F8 operator+(F8 a, F8 b) { return _mm256_add_ps(a.v, b.v); }
PSC_AVX F8 operator-(F8 a, F8 b) { return _mm256_sub_ps(a.v, b.v); }
PSC_AVX F8 operator*(F8 a, F8 b) { return _mm256_mul_ps(a.v, b.v); }
PSC_AVX F8 operator/(F8 a, F8 b) { return _mm256_div_ps(a.v, b.v); }
PSC_AVX F8 sqrt(F8 a) { return _mm256_sqrt_ps(a.v); }
PSC_AVX M8 le(F8 a, F8 b) { return {_mm256_cmp_ps(a.v, b.v, _CMP_LE_OQ)}; }
PSC_AVX M8 ge(F8 a, F8 b) { return {_mm256_cmp_ps(a.v, b.v, _CMP_GE_OQ)}; }
PSC_AVX M8 gt(F8 a, F8 b) { return {_mm256_cmp_ps(a.v, b.v, _CMP_GT_OQ)}; }
PSC_AVX M8 lt(F8 a, F8 b) { return {_mm256_cmp_ps(a.v, b.v, _CMP_LT_OQ)}; }
PSC_AVX M8 notGreater(F8 a, F8 b) { return {_mm256_cmp_ps(a.v, b.v, _CMP_NGT_UQ)}; }  // !(a > b)
PSC_AVX M8 both(M8 a, M8 b) { return {_mm256_and_ps(a.m, b.m)}; }
PSC_AVX M8 either(M8 a, M8 b) { return {_mm256_or_ps(a.m, b.m)}; }
PSC_AVX F8 select(M8 m, F8 if_true, F8 if_false) {  // as pick above: no blendv
  return _mm256_or_ps(_mm256_and_ps(m.m, if_true.v), _mm256_andnot_ps(m.m, if_false.v));
}

}  // namespace
}  // namespace psc::bullet::detail

#include "robust_kernel.h"

namespace psc::bullet::detail {
namespace {

/// Lanes [from, from + 4) of a float array, as doubles (exactly).
PSC_AVX D4 widen(const float* lanes, int from) { return _mm256_cvtps_pd(_mm_load_ps(lanes + from)); }

void robustLanesAvx(const VfLanesIn& in, const float* margin, std::uint32_t lanes, float kshr0, float kshr1,
                    RobustLanesOut& out) {
  // Robust's single-precision contact (robust_kernel.h) in all eight lanes at once: one pass of
  // floats instead of up to two of four doubles, the lanes' own bits kept at the end. The corners
  // relative to the node, as robustContact takes them: p = 0.
  const RobustV3<F8> o{_mm256_load_ps(in.ox), _mm256_load_ps(in.oy), _mm256_load_ps(in.oz)};
  const RobustV3<F8> p{_mm256_setzero_ps(), _mm256_setzero_ps(), _mm256_setzero_ps()};
  const RobustV3<F8> a = minus(RobustV3<F8>{_mm256_load_ps(in.ax), _mm256_load_ps(in.ay), _mm256_load_ps(in.az)}, o);
  const RobustV3<F8> b = minus(RobustV3<F8>{_mm256_load_ps(in.bx), _mm256_load_ps(in.by), _mm256_load_ps(in.bz)}, o);
  const RobustV3<F8> c = minus(RobustV3<F8>{_mm256_load_ps(in.cx), _mm256_load_ps(in.cy), _mm256_load_ps(in.cz)}, o);
  const M8 needs_double = robustNeedsDouble(a, b, c);
  F8 wa, wb, wc, distance2;
  robustClosest(p, a, b, c, wa, wb, wc, distance2);
  const F8 radius{_mm256_load_ps(margin)};
  const M8 within = lt(distance2, radius * radius);
  RobustV3<F8> n;
  const M8 short_away = robustNormal(p, a, b, c, wa, wb, wc, radius, F8(kSingleShort), F8(kSingleFaceShort), n);
  _mm256_store_ps(out.wx, wa.v);
  _mm256_store_ps(out.wy, wb.v);
  _mm256_store_ps(out.wz, wc.v);
  _mm256_store_ps(out.nx, n.x.v);
  _mm256_store_ps(out.ny, n.y.v);
  _mm256_store_ps(out.nz, n.z.v);
  // fillContact's masses and constraint mixing at these weights, as lanesAvx has them for Bullet's.
  const __m256 moves = contactMixing(in, wa.v, wb.v, wc.v, kshr0, kshr1, out.cfm0, out.cfm1);
  out.scalar = static_cast<std::uint32_t>(_mm256_movemask_ps(_mm256_or_ps(needs_double.m, short_away.m))) & lanes;
  out.inside = static_cast<std::uint32_t>(_mm256_movemask_ps(within.m)) & lanes;
  out.moves = static_cast<std::uint32_t>(_mm256_movemask_ps(moves));
}

std::uint32_t crossingRuledOutAvx(const VfLanesIn& in) {
  std::uint32_t out = 0;
  for (int from = 0; from < kVfLanes; from += 4) {
    const RobustV3<D4> p0{widen(in.qx, from), widen(in.qy, from), widen(in.qz, from)};
    const RobustV3<D4> a0{widen(in.aqx, from), widen(in.aqy, from), widen(in.aqz, from)};
    const RobustV3<D4> b0{widen(in.bqx, from), widen(in.bqy, from), widen(in.bqz, from)};
    const RobustV3<D4> c0{widen(in.cqx, from), widen(in.cqy, from), widen(in.cqz, from)};
    const RobustV3<D4> p1{widen(in.ox, from), widen(in.oy, from), widen(in.oz, from)};
    const RobustV3<D4> a1{widen(in.ax, from), widen(in.ay, from), widen(in.az, from)};
    const RobustV3<D4> b1{widen(in.bx, from), widen(in.by, from), widen(in.bz, from)};
    const RobustV3<D4> c1{widen(in.cx, from), widen(in.cy, from), widen(in.cz, from)};
    D4 c[4], scale, tol;
    const M4 ruled_out = crossingRuledOut(p0, a0, b0, c0, p1, a1, b1, c1, c, scale, tol);
    out |= static_cast<std::uint32_t>(_mm256_movemask_pd(ruled_out.m)) << from;
  }
  return out;
}

}  // namespace
}  // namespace psc::bullet::detail
#if defined(__clang__)
#pragma clang attribute pop
#else
#pragma GCC pop_options
#endif
#undef PSC_AVX
#endif

namespace psc::bullet::detail {

bool vfLanesEnabled() {
#if defined(PSC_HAVE_VF_LANES)
  static const bool has = __builtin_cpu_supports("avx") != 0;
  return has && g_allowed.load(std::memory_order_relaxed);
#else
  return false;
#endif
}

void robustLanes(const VfLanesIn& in, const float* margin, std::uint32_t lanes, float kshr0, float kshr1,
                 RobustLanesOut& out) {
#if defined(PSC_HAVE_VF_LANES)
  robustLanesAvx(in, margin, lanes, kshr0, kshr1, out);
#else
  (void)in, (void)margin, (void)lanes, (void)kshr0, (void)kshr1;
  out.inside = 0;
  out.scalar = ~0u;  // never reached: vfLanesEnabled() is false
#endif
}

std::uint32_t crossingRuledOutLanes(const VfLanesIn& in) {
#if defined(PSC_HAVE_VF_LANES)
  return crossingRuledOutAvx(in);
#else
  (void)in;
  return 0;  // never reached: vfLanesEnabled() is false
#endif
}

void allowVfLanes(bool allowed) { g_allowed.store(allowed, std::memory_order_relaxed); }

void vfLanes(const VfLanesIn& in, float mrg, float kshr0, float kshr1, bool robust, bool motion_term, VfLanesOut& out) {
#if defined(PSC_HAVE_VF_LANES)
  lanesAvx(in, mrg, kshr0, kshr1, robust, motion_term, out);
#else
  (void)in, (void)mrg, (void)kshr0, (void)kshr1, (void)robust, (void)motion_term;
  out.contact = out.robust = 0;
  out.scalar = ~0u;  // never reached: vfLanesEnabled() is false
#endif
}

}  // namespace psc::bullet::detail
