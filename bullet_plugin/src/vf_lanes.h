// Private: Bullet's vertex–face test (btSoftColliders::CollideVF_SS::Process, Bullet 3.24,
// single precision) for eight (node, face) pairs at once, with AVX.
//
// Every lane performs Bullet's float operations in Bullet's order (its btVector3 is scalar code on
// this platform: no SSE in the API, and the build has no FMA), and AVX's add, sub, mul, div and
// sqrt round exactly like their scalar forms, so each lane's contact is the one Process would push,
// bit for bit. Bullet's branches become masks: a lane computes both sides and keeps the side Bullet
// takes. tests/bullet/exact_test.cpp checks the equality on random and real pairs.
//
// Why: in the plugin's exact stage almost every candidate is a contact (the candidate stage keeps
// only pairs within the radius), and Process's contact path, five square roots and four divisions
// in a dependent chain, ran at about 145 ns a pair on 8 tori × 2,000 vertices whether the caches
// were warm or not (the stage run twice in a row cost twice as much).
#pragma once

#include <cstdint>

namespace psc::bullet::detail {

inline constexpr int kVfLanes = 8;

/// The inputs of eight pairs, one array per coordinate (structure of arrays).
struct VfLanesIn {
  alignas(32) float ox[kVfLanes], oy[kVfLanes], oz[kVfLanes];  ///< the node's m_x
  alignas(32) float qx[kVfLanes], qy[kVfLanes], qz[kVfLanes];  ///< the node's m_q
  alignas(32) float ax[kVfLanes], ay[kVfLanes], az[kVfLanes];  ///< the face's corners' m_x
  alignas(32) float bx[kVfLanes], by[kVfLanes], bz[kVfLanes];
  alignas(32) float cx[kVfLanes], cy[kVfLanes], cz[kVfLanes];
  alignas(32) float aqx[kVfLanes], aqy[kVfLanes], aqz[kVfLanes];  ///< the corners' m_q (crossingLanes only)
  alignas(32) float bqx[kVfLanes], bqy[kVfLanes], bqz[kVfLanes];
  alignas(32) float cqx[kVfLanes], cqy[kVfLanes], cqz[kVfLanes];
  alignas(32) float im[kVfLanes];                              ///< the node's m_im
  alignas(32) float ia[kVfLanes], ib[kVfLanes], ic[kVfLanes];  ///< the corners' m_im
};

/// What Process would put into the SContact of each lane (m_node, m_face and m_friction are the
/// caller's), and which lanes push one.
struct VfLanesOut {
  alignas(32) float nx[kVfLanes], ny[kVfLanes], nz[kVfLanes];  ///< m_normal
  alignas(32) float wx[kVfLanes], wy[kVfLanes], wz[kVfLanes];  ///< m_weights
  alignas(32) float margin[kVfLanes];                          ///< m_margin
  alignas(32) float cfm0[kVfLanes], cfm1[kVfLanes];            ///< m_cfm
  std::uint32_t contact = 0;  ///< bit i: Process pushes a contact for lane i
  /// Bit i: lane i needs the whole scalar test: Process would accept without ever having set its
  /// projection point (only when the radius squared overflows to infinity).
  std::uint32_t scalar = 0;
  /// Bit i (with `robust` only, never with `scalar`): Robust's own contact decides lane i, at
  /// radius margin[i]: the node lies on the face (distance 0), or Bullet's thresholds skipped a
  /// face or an edge (bulletProjectOrigin's `skipped`) and the pair is beyond Bullet's radius.
  std::uint32_t robust = 0;
};

/// Robust's own contact (robustContact in exact_stage.cpp) for eight lanes, its single-precision
/// part, with the operations of robust_kernel.h, which the scalar test runs too: so each lane's
/// weights and normal are the scalar test's, bit for bit.
struct RobustLanesOut {
  alignas(32) float wx[kVfLanes], wy[kVfLanes], wz[kVfLanes];  ///< the closest point's weights
  alignas(32) float nx[kVfLanes], ny[kVfLanes], nz[kVfLanes];  ///< the unit normal, face to node
  alignas(32) float cfm0[kVfLanes], cfm1[kVfLanes];            ///< m_cfm at these weights (VfLanesOut's)
  /// Bit i: lane i needs the scalar test, whose double path decides it: its face is too thin, too
  /// small or too large for single precision (robustNeedsDouble), or the node lies within a
  /// hundredth of the radius of its closest point (kSingleShort).
  std::uint32_t scalar = 0;
  /// Bit i: the closest point lies within lane i's radius (margin[i]).
  std::uint32_t inside = 0;
  /// Bit i: a side of lane i can move (ma + mb > 0 at these weights): the contact is made.
  std::uint32_t moves = 0;
};

/// Runs the lanes whose bits are set in `lanes` (VfLanesOut::robust) at radii `margin`
/// (VfLanesOut::margin), all eight in one pass; the bits of the other lanes in `out.scalar` and
/// `out.inside` are 0 (cfm0, cfm1 and `moves` are computed for all eight). `kshr0` / `kshr1` as
/// for vfLanes. Only call when vfLanesEnabled().
void robustLanes(const VfLanesIn& in, const float* margin, std::uint32_t lanes, float kshr0, float kshr1,
                 RobustLanesOut& out);

/// Continuous's crossing test, its first part for eight lanes (robust_kernel.h's crossingRuledOut,
/// which firstCrossing runs too, in the same operations): bit i set where the node of lane i
/// cannot have passed through the face during the step (m_q → m_x, the corners' m_q included), so
/// that firstCrossing would find no crossing. Only call when vfLanesEnabled().
std::uint32_t crossingRuledOutLanes(const VfLanesIn& in);

/// True when this processor runs the AVX kernel (and tests have not switched it off).
bool vfLanesEnabled();
/// Tests: false makes vfLanesEnabled() false, so the exact stage runs Process pair by pair.
void allowVfLanes(bool allowed);

/// Runs the eight lanes. `mrg`: the contact radius without motion (CollideVF_SS::mrg); `kshr0` /
/// `kshr1`: m_cfg.kSHR of the node's and the face's body. `robust`: also flag Robust's lanes in
/// `scalar`. The radius is Bullet's, mrg + 2·|m_x − m_q|; without `motion_term` mrg alone
/// (Continuous on a body against itself). Only call when vfLanesEnabled().
void vfLanes(const VfLanesIn& in, float mrg, float kshr0, float kshr1, bool robust, bool motion_term, VfLanesOut& out);

}  // namespace psc::bullet::detail
