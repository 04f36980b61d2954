#include "exact_stage.h"

#include "robust_kernel.h"
#include "vf_lanes.h"

#include "psc/bullet/exact.h"
#include "psc/error.h"

// CollideVF_SS leaves its projection point uninitialised when the face is degenerate (it then
// never reads it); GCC's -Wmaybe-uninitialized sees that once the header is inlined here, and it
// reports at the header's lines, so the region must enclose Bullet's first inclusion in this file.
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wmaybe-uninitialized"
#include <BulletSoftBody/btSoftBody.h>
#include <BulletSoftBody/btSoftBodyInternals.h>
#pragma GCC diagnostic pop

#include <algorithm>
#include <cassert>
#include <cmath>
#include <cstdint>
#include <string>
#include <vector>

namespace psc::bullet {
namespace {

Vec3 toVec(const btVector3& v) { return {double(v.x()), double(v.y()), double(v.z())}; }
btVector3 toBt(const Vec3& v) { return btVector3(btScalar(v.x()), btScalar(v.y()), btScalar(v.z())); }

/// The face half of Bullet's ProjectOrigin(a, b, c, prj, sqd) (btSoftBodyInternals.h), the same
/// operations in the same order (so the same bits), also reporting whether Bullet's size
/// thresholds skipped something that could hold the closest point: the face (|q|² ≤ SIMD_EPSILON)
/// or, when the projection fell outside, an edge (|d|² ≤ SIMD_EPSILON).
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wmaybe-uninitialized"
inline void bulletProjectOrigin(const btVector3& a, const btVector3& b, const btVector3& c, btVector3& prj,
                                btScalar& sqd, bool& skipped) {
  const btVector3& q = btCross(b - a, c - a);
  const btScalar m2 = q.length2();
  if (m2 > SIMD_EPSILON) {
    const btVector3 n = q / btSqrt(m2);
    const btScalar k = btDot(a, n);
    const btScalar k2 = k * k;
    if (k2 < sqd) {
      const btVector3 p = n * k;
      if ((btDot(btCross(a - p, b - p), q) > 0) && (btDot(btCross(b - p, c - p), q) > 0) &&
          (btDot(btCross(c - p, a - p), q) > 0)) {
        prj = p;
        sqd = k2;
      } else {
        skipped = !((b - a).length2() > SIMD_EPSILON) || !((c - b).length2() > SIMD_EPSILON) ||
                  !((a - c).length2() > SIMD_EPSILON);
        ProjectOrigin(a, b, prj, sqd);
        ProjectOrigin(b, c, prj, sqd);
        ProjectOrigin(c, a, prj, sqd);
      }
    }
  } else {
    skipped = true;
  }
}
#pragma GCC diagnostic pop

/// What every exact test needs of one pair, as CollideVF_SS sets it up.
struct PairContext {
  const btSoftBody* psb[2];  // node's body, face's body
  btScalar mrg;              // contact radius without motion: the margins' sum, or the self contact radius
  // Bullet's motion term, 2·|m_x − m_q|, in the discrete radius. Not for Continuous on a body
  // against itself: there a body's speed is no reason to touch itself (the core's self rule has its
  // own motion term), and Continuous's crossing test stands in for it (motionTermFor).
  bool motion_term = true;
};

bool motionTermFor(ExactTest test, const btSoftBody& node_body, const btSoftBody& face_body) {
  return !(test == ExactTest::Continuous && &node_body == &face_body);
}

/// The fields CollideVF_SS fills after its distance test, for weights w and normal `normal`.
/// False (no contact) when neither side can move, as in Bullet.
/// Every field of a contact, as CollideVF_SS sets them, the constraint mixing already computed.
void setContact(const PairContext& ctx, const btSoftBody::Node& node, const btSoftBody::Face& face, const btVector3& w,
                const btVector3& normal, btScalar margin, btScalar cfm0, btScalar cfm1, btSoftBody::SContact& c) {
  c.m_normal = normal;
  c.m_margin = margin;
  c.m_node = const_cast<btSoftBody::Node*>(&node);
  c.m_face = const_cast<btSoftBody::Face*>(&face);
  c.m_weights = w;
  c.m_friction = btMax(ctx.psb[0]->m_cfg.kDF, ctx.psb[1]->m_cfg.kDF);
  c.m_cfm[0] = cfm0;
  c.m_cfm[1] = cfm1;
}

bool fillContact(const PairContext& ctx, const btSoftBody::Node& node, const btSoftBody::Face& face,
                 const btVector3& w, const btVector3& normal, btScalar margin, btSoftBody::SContact& c) {
  const btSoftBody::Node* n[] = {face.m_n[0], face.m_n[1], face.m_n[2]};
  const btScalar ma = node.m_im;
  btScalar mb = BaryEval(n[0]->m_im, n[1]->m_im, n[2]->m_im, w);
  if ((n[0]->m_im <= 0) || (n[1]->m_im <= 0) || (n[2]->m_im <= 0)) mb = 0;
  const btScalar ms = ma + mb;
  if (!(ms > 0)) return false;
  setContact(ctx, node, face, w, normal, margin, ma / ms * ctx.psb[0]->m_cfg.kSHR, mb / ms * ctx.psb[1]->m_cfg.kSHR, c);
  return true;
}

/// The node's motion relative to the face's material point with weights w over the step.
Vec3 relativeMotion(const btSoftBody::Node& node, const btSoftBody::Face& face, const std::array<double, 3>& w) {
  Vec3 face_motion = Vec3::Zero();
  for (int i = 0; i < 3; ++i) face_motion += w[i] * (toVec(face.m_n[i]->m_x) - toVec(face.m_n[i]->m_q));
  return (toVec(node.m_x) - toVec(node.m_q)) - face_motion;
}

Vec3 facePoint(const btSoftBody::Face& face, const std::array<double, 3>& w, bool previous) {
  Vec3 p = Vec3::Zero();
  for (int i = 0; i < 3; ++i) p += w[i] * toVec(previous ? face.m_n[i]->m_q : face.m_n[i]->m_x);
  return p;
}

/// Every position of the pair (m_x and m_q of the node and the face's corners) is finite.
bool finitePair(const btSoftBody::Node& node, const btSoftBody::Face& face) {
  const auto finite = [](const btSoftBody::Node& n) {
    return std::isfinite(n.m_x.x()) && std::isfinite(n.m_x.y()) && std::isfinite(n.m_x.z()) &&
           std::isfinite(n.m_q.x()) && std::isfinite(n.m_q.y()) && std::isfinite(n.m_q.z());
  };
  return finite(node) && finite(*face.m_n[0]) && finite(*face.m_n[1]) && finite(*face.m_n[2]);
}

/// The unit normal of the face at its current positions, or zero when it is degenerate relative
/// to its own size.
Vec3 faceNormal(const Vec3& a, const Vec3& b, const Vec3& c) {
  const Vec3 n = (b - a).cross(c - a);
  const double l2 = std::max({(b - a).squaredNorm(), (c - b).squaredNorm(), (a - c).squaredNorm()});
  const double n2 = n.squaredNorm();
  return n2 > 1e-24 * l2 * l2 ? Vec3(n / std::sqrt(n2)) : Vec3::Zero();
}

/// A unit normal for a node that lies on the face (no direction from the distance): the face's
/// normal towards the side the node was on at the step's start (else against its relative motion);
/// a degenerate face: against the relative motion, else perpendicular to the face's longest edge.
Vec3 normalWithoutDistance(const btSoftBody::Node& node, const btSoftBody::Face& face,
                           const std::array<double, 3>& w) {
  const Vec3 a = toVec(face.m_n[0]->m_x), b = toVec(face.m_n[1]->m_x), c = toVec(face.m_n[2]->m_x);
  const Vec3 motion = relativeMotion(node, face, w);
  Vec3 n = faceNormal(a, b, c);
  if (n != Vec3::Zero()) {
    const double side = n.dot(toVec(node.m_q) - facePoint(face, w, true));
    if (side < 0.0 || (side == 0.0 && n.dot(motion) > 0.0)) n = -n;
    return n;
  }
  const double m = motion.norm();
  if (m > 0.0) return -motion / m;
  Vec3 e = b - a;
  if ((c - b).squaredNorm() > e.squaredNorm()) e = c - b;
  if ((a - c).squaredNorm() > e.squaredNorm()) e = a - c;
  if (e == Vec3::Zero()) return Vec3::UnitZ();
  Eigen::Index axis = 0;
  e.cwiseAbs().minCoeff(&axis);
  return e.cross(Vec3::Unit(axis)).normalized();
}

ContactKind robustContact(const PairContext& ctx, const btSoftBody::Node& node, const btSoftBody::Face& face,
                          btScalar m, btSoftBody::SContact& contact);

/// Bullet's CollideVF_SS decision and contact (Robust = false), or Robust's (true): both at
/// Bullet's radius, margins + 2·|m_x − m_q| (without ctx.motion_term, the margins alone).
ContactKind discreteTest(bool robust, const PairContext& ctx, const btSoftBody::Node& node,
                         const btSoftBody::Face& face, btSoftBody::SContact& contact) {
  const btVector3 o = node.m_x;
  btVector3 p(0, 0, 0);  // read only when d was set, i.e. together with p
  btScalar d = SIMD_INFINITY;
  bool skipped = false;
  bulletProjectOrigin(face.m_n[0]->m_x - o, face.m_n[1]->m_x - o, face.m_n[2]->m_x - o, p, d, skipped);
  const btScalar m = ctx.motion_term ? ctx.mrg + (o - node.m_q).length() * 2 : ctx.mrg;
  if (d < (m * m)) {
    if (!robust || d > 0) {
      const btSoftBody::Node* n[] = {face.m_n[0], face.m_n[1], face.m_n[2]};
      const btVector3 w = BaryCoord(n[0]->m_x, n[1]->m_x, n[2]->m_x, p + o);
      return fillContact(ctx, node, face, w, p / -btSqrt(d), m, contact) ? ContactKind::Bullet : ContactKind::None;
    }
  } else if (!robust || !skipped) {
    return ContactKind::None;
  }
  return robustContact(ctx, node, face, m, contact);
}

/// Robust's own contact at radius m, where Bullet skipped the face or an edge as too small, or
/// found the node exactly on the face: the closest point in single precision from Bullet's float
/// positions (robust_kernel.h: relative to the triangle and the distance, at any scale), else,
/// where that cannot hold, the exact closest point in double. With single-precision Bullet the
/// single-precision part runs the operations of detail::robustLanes (vf_lanes.cpp), which decides
/// most such pairs, so either gives the same contact bit for bit.
ContactKind robustContact(const PairContext& ctx, const btSoftBody::Node& node, const btSoftBody::Face& face,
                          btScalar m, btSoftBody::SContact& contact) {
  // A non-finite corner or radius (a review's finding, stop 46: an infinite corner gave a NaN
  // normal) has no closest point to speak of.
  if (!std::isfinite(m) || !finitePair(node, face)) return ContactKind::None;
  if constexpr (sizeof(btScalar) == sizeof(float)) {
    using F3 = detail::RobustV3<float>;
    // Relative to the node (robust_kernel.h), as the lanes compute it: p = 0.
    const btVector3& o = node.m_x;
    const auto f3 = [&o](const btVector3& v) {
      return F3{static_cast<float>(v.x() - o.x()), static_cast<float>(v.y() - o.y()), static_cast<float>(v.z() - o.z())};
    };
    const F3 p{0.0f, 0.0f, 0.0f}, a = f3(face.m_n[0]->m_x), b = f3(face.m_n[1]->m_x), c = f3(face.m_n[2]->m_x);
    if (!detail::robustNeedsDouble(a, b, c)) {
      float wa = 0.0f, wb = 0.0f, wc = 0.0f, distance2 = 0.0f;
      detail::robustClosest(p, a, b, c, wa, wb, wc, distance2);
      const auto radius = static_cast<float>(m);
      if (!(distance2 < radius * radius)) return ContactKind::None;
      F3 n;
      if (!detail::robustNormal(p, a, b, c, wa, wb, wc, radius, float(detail::kSingleShort),
                                 float(detail::kSingleFaceShort), n))
        return fillContact(ctx, node, face, btVector3(wa, wb, wc), btVector3(n.x, n.y, n.z), m, contact)
                   ? ContactKind::Robust
                   : ContactKind::None;
    }
  }
  const Vec3 po = toVec(node.m_x), a = toVec(face.m_n[0]->m_x), b = toVec(face.m_n[1]->m_x),
             c = toVec(face.m_n[2]->m_x);
  const ClosestPoint cp = closestPointOnTriangle(po, a, b, c);
  const double radius = double(m);
  if (!(cp.distance2 < radius * radius)) return ContactKind::None;
  using detail::robustV3;
  detail::RobustV3<double> n;
  const bool short_away = detail::robustNormal(robustV3(po), robustV3(a), robustV3(b), robustV3(c), cp.weights[0],
                                               cp.weights[1], cp.weights[2], radius, detail::kDoubleShort,
                                               detail::kDoubleFaceShort, n);
  const Vec3 normal = short_away ? normalWithoutDistance(node, face, cp.weights) : Vec3(n.x, n.y, n.z);
  const btVector3 w{btScalar(cp.weights[0]), btScalar(cp.weights[1]), btScalar(cp.weights[2])};
  return fillContact(ctx, node, face, w, toBt(normal), m, contact) ? ContactKind::Robust : ContactKind::None;
}

/// Continuous: a node that passed through the face during the step (and ends behind it) gets a
/// contact back to the side it came from, replacing the discrete one; otherwise Robust's test, at
/// Bullet's radius. (Until 2026-11-26 the discrete part had the margins alone, without Bullet's
/// motion term, so as not to throw fast nodes back at twice their step; with the band's weights
/// shared (Settings::runaway_sharing, crowded_band) the motion term's push is what keeps fast
/// bodies from crossing edge through face, which no vertex–face crossing test sees:
/// docs/DECISIONS.md, "Continuous keeps Bullet's radius".)
ContactKind crossingOver(const PairContext& ctx, const btSoftBody::Node& node, const btSoftBody::Face& face,
                         ContactKind discrete, btSoftBody::SContact& contact);

ContactKind continuousTest(const PairContext& ctx, const btSoftBody::Node& node, const btSoftBody::Face& face,
                           btSoftBody::SContact& contact) {
  return crossingOver(ctx, node, face, discreteTest(true, ctx, node, face, contact), contact);
}

/// Continuous's second half: given the discrete test's outcome (`discrete`, `contact`), the
/// crossing contact that replaces it when the node passed through the face during the step.
ContactKind crossingOver(const PairContext& ctx, const btSoftBody::Node& node, const btSoftBody::Face& face,
                         ContactKind discrete, btSoftBody::SContact& contact) {
  const std::array<Vec3, 4> start{toVec(node.m_q), toVec(face.m_n[0]->m_q), toVec(face.m_n[1]->m_q),
                                  toVec(face.m_n[2]->m_q)};
  const std::array<Vec3, 4> end{toVec(node.m_x), toVec(face.m_n[0]->m_x), toVec(face.m_n[1]->m_x),
                                toVec(face.m_n[2]->m_x)};
  const std::optional<Crossing> crossing = firstCrossing(start, end);
  // A node that came back through the face within the step (a review's finding, stop 46: a face
  // turning under a node that passes at a shallow angle) is on its own side: no push. The side
  // below is judged with today's normal against the start positions, not in the face's own frame
  // of each time: on a cloth hit by a fast ball, whose faces turn by up to 2.7 rad in a step, the
  // face's own frame left a node that crossed it and came back across its plane beside it (behind
  // the surface there) with no crossing contact, and 85 vertices tunnelled against none
  // (docs/DECISIONS.md, "Stop 46").
  if (!crossing || crossing->returns % 2 == 1) return discrete;
  const std::array<double, 3>& w = crossing->weights;
  // The normal: the face's at the end of the step (else at the crossing, else at the start),
  // towards the side the node started on; a node starting in the plane: against its motion.
  Vec3 n = faceNormal(end[1], end[2], end[3]);
  const auto at = [&](int i, double t) { return Vec3(start[i] + t * (end[i] - start[i])); };
  if (n == Vec3::Zero()) n = faceNormal(at(1, crossing->t), at(2, crossing->t), at(3, crossing->t));
  if (n == Vec3::Zero()) n = faceNormal(start[1], start[2], start[3]);
  const Vec3 motion = relativeMotion(node, face, w);
  if (n == Vec3::Zero()) {
    if (motion == Vec3::Zero()) return discrete;
    n = -motion.normalized();
  }
  const double side0 = n.dot(start[0] - facePoint(face, w, true));
  if (side0 < 0.0 || (side0 == 0.0 && n.dot(motion) > 0.0)) n = -n;
  // Only a node that ends the step through the face: one that came back needs no push.
  if (!(n.dot(end[0] - facePoint(face, w, false)) < 0.0)) return discrete;
  const btVector3 bw{btScalar(w[0]), btScalar(w[1]), btScalar(w[2])};
  btSoftBody::SContact crossing_contact;
  if (!fillContact(ctx, node, face, bw, toBt(n), ctx.mrg, crossing_contact)) return discrete;
  contact = crossing_contact;
  return ContactKind::Crossing;
}

btScalar marginSum(const btSoftBody& node_body, const btSoftBody& face_body) {
  return node_body.getCollisionShape()->getMargin() + face_body.getCollisionShape()->getMargin();
}

PairContext contextOf(const btSoftBody& node_body, const btSoftBody& face_body) {
  return {{&node_body, &face_body}, marginSum(node_body, face_body)};
}

}  // namespace

const char* toString(ExactTest test) {
  switch (test) {
    case ExactTest::Bullet: return "bullet";
    case ExactTest::Robust: return "robust";
    case ExactTest::Continuous: return "continuous";
  }
  return "?";
}

const char* toString(ContactSet set) {
  switch (set) {
    case ContactSet::AllPairs: return "all";
    case ContactSet::NearestFace: return "nearest";
  }
  return "?";
}

ExactTest exactTestFromString(const std::string& text) {
  for (ExactTest t : {ExactTest::Bullet, ExactTest::Robust, ExactTest::Continuous})
    if (text == toString(t)) return t;
  throw psc::Error(psc::ErrorCode::InvalidArgument,
                   "exact test '" + text + "' is not one of bullet, robust, continuous");
}

ContactKind exactContact(ExactTest test, const btSoftBody& node_body, const btSoftBody::Node& node,
                         const btSoftBody& face_body, const btSoftBody::Face& face, btSoftBody::SContact& contact) {
  PairContext ctx = contextOf(node_body, face_body);
  if (!std::isfinite(ctx.mrg) || !finitePair(node, face)) return ContactKind::None;
  ctx.motion_term = motionTermFor(test, node_body, face_body);
  switch (test) {
    case ExactTest::Bullet: return discreteTest(false, ctx, node, face, contact);
    case ExactTest::Robust: return discreteTest(true, ctx, node, face, contact);
    case ExactTest::Continuous: return continuousTest(ctx, node, face, contact);
  }
  return ContactKind::None;
}

ExactCounts collideCandidates(ExactTest test, btSoftBody& node_body, btSoftBody& face_body,
                              const psc::CandidatePair* first, const psc::CandidatePair* last, ContactSet contacts) {
  return collideCandidates(test, node_body, face_body, marginSum(node_body, face_body), first, last, contacts);
}

namespace {

/// The squared distance, in btScalar, from a contact's node to its face's point at the contact's
/// weights (BaryEval's order, as PSolve_SContacts evaluates the face point).
btScalar contactDistance2(const btSoftBody::SContact& c) {
  const btSoftBody::Face& f = *c.m_face;
  const btVector3 p = f.m_n[0]->m_x * c.m_weights.x() + f.m_n[1]->m_x * c.m_weights.y() + f.m_n[2]->m_x * c.m_weights.z();
  return (c.m_node->m_x - p).length2();
}

/// ContactSet::NearestFace on node_body.m_scontacts[from, end): of each node's contacts there, the
/// discrete contact nearest to the node (the first of equals) and every crossing contact
/// (`is_crossing`, parallel to the range; null: none) stay, in order. A node's contacts need not be
/// consecutive (the core's candidates come by region and chunk pair). Returns how many went.
std::size_t keepNearestFace(btSoftBody& node_body, int from, const std::vector<char>* is_crossing) {
  btAlignedObjectArray<btSoftBody::SContact>& list = node_body.m_scontacts;
  const int end = list.size();
  if (end - from < 2) return 0;
  const auto crossing = [&](int i) { return is_crossing != nullptr && (*is_crossing)[static_cast<std::size_t>(i - from)]; };
  // Per node of the body, the index of its nearest discrete contact so far (-1: none yet).
  thread_local std::vector<int> nearest;
  thread_local std::vector<btScalar> least;
  const btSoftBody::Node* nodes = &node_body.m_nodes[0];
  const auto nodeOf = [&](int i) { return static_cast<std::size_t>(list[i].m_node - nodes); };
  const auto count = static_cast<std::size_t>(node_body.m_nodes.size());
  if (nearest.size() < count) {
    nearest.resize(count, -1);
    least.resize(count);
  }
  for (int i = from; i < end; ++i) {
    if (crossing(i)) continue;
    const std::size_t n = nodeOf(i);
    const btScalar d = contactDistance2(list[i]);
    if (nearest[n] < 0 || d < least[n]) {
      nearest[n] = i;
      least[n] = d;
    }
  }
  int out = from;
  for (int i = from; i < end; ++i)
    if (crossing(i) || nearest[nodeOf(i)] == i) list[out++] = list[i];
  for (int i = from; i < out; ++i) nearest[nodeOf(i)] = -1;  // every node touched kept a contact
  list.resize(out);
  return static_cast<std::size_t>(end - out);
}

}  // namespace

#if !defined(BT_USE_DOUBLE_PRECISION)
namespace {

/// The exact stage eight candidates at a time (detail::vfLanes), in candidate order. Each
/// candidate's outcome goes to take(node, kind, contact); Bullet's test where the lanes cannot
/// decide runs Process itself, which pushes its contact. Robust's own contacts come from
/// detail::robustLanes (the scalar robustContact where a face is degenerate or the node lies on
/// it); without the crossing test they, like Bullet's, are written in place, counted in
/// `robust_in_place`. Robust and Continuous run their scalar discrete test where the lanes cannot
/// decide; Continuous then adds its crossing test to every lane. The tail (fewer than eight) runs
/// the scalar tests.
template <class Take>
void collideInLanes(ExactTest test, const PairContext& ctx, btSoftBody& node_body, btSoftBody& face_body,
                    const psc::CandidatePair* first, const psc::CandidatePair* last, Take&& take,
                    std::size_t& robust_in_place) {
  static_assert(sizeof(btScalar) == sizeof(float), "the lanes are single precision");
  namespace d = detail;
  const bool robust = test != ExactTest::Bullet;
  const bool continuous = test == ExactTest::Continuous;
  const btSoftBody::Node* nodes = &node_body.m_nodes[0];
  const btSoftBody::Face* faces = &face_body.m_faces[0];
  btSoftColliders::CollideVF_SS collide;
  collide.mrg = ctx.mrg;
  collide.psb[0] = &node_body;
  collide.psb[1] = &face_body;
  btDbvtNode node_leaf{};
  btDbvtNode face_leaf{};
  btSoftBody::SContact contact;
  // The scalar discrete test of one candidate (Bullet's: Process pushes; returns None).
  const auto discrete = [&](const btSoftBody::Node& node, const btSoftBody::Face& face) {
    if (!robust) {
      node_leaf.data = const_cast<btSoftBody::Node*>(&node);
      face_leaf.data = const_cast<btSoftBody::Face*>(&face);
      collide.Process(&node_leaf, &face_leaf);
      return ContactKind::None;
    }
    return discreteTest(true, ctx, node, face, contact);
  };
  // `may_cross`: false where the lanes ruled a crossing out (Continuous only).
  const auto finish = [&](const btSoftBody::Node& node, const btSoftBody::Face& face, ContactKind kind,
                          bool may_cross) {
    if (continuous && may_cross) kind = crossingOver(ctx, node, face, kind, contact);
    take(node, kind, contact);
  };
  d::VfLanesIn in;
  d::VfLanesOut out;
  d::RobustLanesOut rob;
  constexpr std::ptrdiff_t kAhead = 2 * d::kVfLanes;
  const psc::CandidatePair* c = first;
  for (; last - c >= d::kVfLanes; c += d::kVfLanes) {
    for (int l = 0; l < d::kVfLanes; ++l) {
      if (last - c > kAhead + l) {
        const psc::CandidatePair& ahead = c[kAhead + l];
        __builtin_prefetch(&faces[ahead.triangle]);
        __builtin_prefetch(&nodes[ahead.vertex].m_x);
        __builtin_prefetch(&nodes[ahead.vertex].m_q);
        __builtin_prefetch(&nodes[ahead.vertex].m_im);
      }
      if (last - c > d::kVfLanes + l) {
        for (const btSoftBody::Node* n : faces[c[d::kVfLanes + l].triangle].m_n) {
          __builtin_prefetch(&n->m_x);
          __builtin_prefetch(&n->m_im);
        }
      }
      assert(static_cast<int>(c[l].vertex) < node_body.m_nodes.size());
      assert(static_cast<int>(c[l].triangle) < face_body.m_faces.size());
      const btSoftBody::Node& node = nodes[c[l].vertex];
      const btSoftBody::Face& face = faces[c[l].triangle];
      in.ox[l] = node.m_x.x(), in.oy[l] = node.m_x.y(), in.oz[l] = node.m_x.z();
      in.qx[l] = node.m_q.x(), in.qy[l] = node.m_q.y(), in.qz[l] = node.m_q.z();
      in.im[l] = node.m_im;
      const btSoftBody::Node& na = *face.m_n[0];
      const btSoftBody::Node& nb = *face.m_n[1];
      const btSoftBody::Node& nc = *face.m_n[2];
      in.ax[l] = na.m_x.x(), in.ay[l] = na.m_x.y(), in.az[l] = na.m_x.z(), in.ia[l] = na.m_im;
      in.bx[l] = nb.m_x.x(), in.by[l] = nb.m_x.y(), in.bz[l] = nb.m_x.z(), in.ib[l] = nb.m_im;
      in.cx[l] = nc.m_x.x(), in.cy[l] = nc.m_x.y(), in.cz[l] = nc.m_x.z(), in.ic[l] = nc.m_im;
      if (continuous) {
        in.aqx[l] = na.m_q.x(), in.aqy[l] = na.m_q.y(), in.aqz[l] = na.m_q.z();
        in.bqx[l] = nb.m_q.x(), in.bqy[l] = nb.m_q.y(), in.bqz[l] = nb.m_q.z();
        in.cqx[l] = nc.m_q.x(), in.cqy[l] = nc.m_q.y(), in.cqz[l] = nc.m_q.z();
      }
    }
    d::vfLanes(in, ctx.mrg, node_body.m_cfg.kSHR, face_body.m_cfg.kSHR, robust, ctx.motion_term, out);
    // Continuous: the lanes whose node cannot have passed through the face keep the discrete
    // outcome (firstCrossing would return no crossing, by the same operations).
    const std::uint32_t crossing_ruled_out = continuous ? d::crossingRuledOutLanes(in) : 0xFFu;
    if ((out.contact | out.scalar | out.robust) == 0 && crossing_ruled_out == 0xFFu) continue;
    if (out.robust != 0) d::robustLanes(in, out.margin, out.robust, node_body.m_cfg.kSHR, face_body.m_cfg.kSHR, rob);
    for (int l = 0; l < d::kVfLanes; ++l) {
      const std::uint32_t bit = 1u << l;
      const btSoftBody::Node& node = nodes[c[l].vertex];
      const btSoftBody::Face& face = faces[c[l].triangle];
      ContactKind kind = ContactKind::None;
      if (out.robust & bit) {
        if (rob.scalar & bit) {
          kind = robustContact(ctx, node, face, out.margin[l], contact);
        } else if (rob.inside & rob.moves & bit) {
          // robustContact's contact (fillContact's), all of it from the lanes; without the crossing
          // test written where it goes, as Bullet's contacts below.
          btSoftBody::SContact& into = continuous ? contact : node_body.m_scontacts.expandNonInitializing();
          setContact(ctx, node, face, btVector3(rob.wx[l], rob.wy[l], rob.wz[l]),
                     btVector3(rob.nx[l], rob.ny[l], rob.nz[l]), out.margin[l], rob.cfm0[l], rob.cfm1[l], into);
          if (!continuous) {
            ++robust_in_place;
            continue;
          }
          kind = ContactKind::Robust;
        }
      } else if (out.scalar & bit) {
        kind = discrete(node, face);
      } else if (out.contact & bit) {
        // Without the crossing test nothing more is done with the contact: it is written where it
        // goes. (Written field by field into a local and then copied, each copy read the contact
        // back across those narrower writes, a store-forwarding stall on every contact: the exact
        // stage took 0.39 ms a step on 8 tori x 2,000 vertices with it, 0.36 without.)
        btSoftBody::SContact& into = continuous ? contact : node_body.m_scontacts.expandNonInitializing();
        setContact(ctx, node, face, btVector3(out.wx[l], out.wy[l], out.wz[l]), btVector3(out.nx[l], out.ny[l], out.nz[l]),
                   out.margin[l], out.cfm0[l], out.cfm1[l], into);
        if (!continuous) continue;
        kind = ContactKind::Bullet;
      }
      finish(node, face, kind, (crossing_ruled_out & bit) == 0);
    }
  }
  for (; c != last; ++c) {
    const btSoftBody::Node& node = nodes[c->vertex];
    const btSoftBody::Face& face = faces[c->triangle];
    finish(node, face, discrete(node, face), true);
  }
}

}  // namespace
#endif

ExactCounts collideCandidates(ExactTest test, btSoftBody& node_body, btSoftBody& face_body, btScalar radius,
                              const psc::CandidatePair* first, const psc::CandidatePair* last, ContactSet contacts) {
  ExactCounts counts;
  if (first == last) return counts;
  // Every index in range, checked before any is read (a review's finding, stop 46: candidates of
  // an earlier step used after a body's arrays shrank read past them).
  bool out_of_range = false;
  const auto node_count = static_cast<std::uint64_t>(node_body.m_nodes.size());
  const auto face_count = static_cast<std::uint64_t>(face_body.m_faces.size());
  for (const psc::CandidatePair* c = first; c != last; ++c)
    out_of_range |= (std::uint64_t{c->vertex} >= node_count) | (std::uint64_t{c->triangle} >= face_count);
  if (out_of_range)
    throw psc::Error(psc::ErrorCode::InvalidArgument,
                     "collideCandidates: a candidate's node or face index is beyond the bodies' m_nodes (" +
                         std::to_string(node_count) + ") or m_faces (" + std::to_string(face_count) +
                         "): candidates of another step or another body");
  const int before = node_body.m_scontacts.size();
  counts.tests = static_cast<std::size_t>(last - first);
  bool lanes = false;
#if !defined(BT_USE_DOUBLE_PRECISION)
  lanes = detail::vfLanesEnabled();
#endif
  if (test == ExactTest::Bullet && !lanes) {
    btSoftColliders::CollideVF_SS collide;
    collide.mrg = radius;
    collide.psb[0] = &node_body;
    collide.psb[1] = &face_body;
    // CollideVF_SS::Process only reads the leaves' data pointers, so two stub leaves stand in for
    // the trees' leaves (verified to reproduce Bullet's contacts field for field).
    btDbvtNode node_leaf{};
    btDbvtNode face_leaf{};
    // The nodes and faces of a body lie far apart in memory and the pairs come in vertex order, so
    // nearly every face and its corners miss the cache: fetch a face a few pairs ahead and its
    // corners (read from the face fetched before) a little closer.
    const btSoftBody::Node* nodes = &node_body.m_nodes[0];
    const btSoftBody::Face* faces = &face_body.m_faces[0];
    constexpr std::ptrdiff_t kFaceAhead = 8, kCornersAhead = 4;
    for (const psc::CandidatePair* c = first; c != last; ++c) {
      if (last - c > kFaceAhead) {
        __builtin_prefetch(&faces[c[kFaceAhead].triangle]);
        __builtin_prefetch(&nodes[c[kFaceAhead].vertex].m_x);
      }
      if (last - c > kCornersAhead) {
        const btSoftBody::Face& ahead = faces[c[kCornersAhead].triangle];
        for (const btSoftBody::Node* n : ahead.m_n) __builtin_prefetch(&n->m_x);
      }
      assert(static_cast<int>(c->vertex) < node_body.m_nodes.size());
      assert(static_cast<int>(c->triangle) < face_body.m_faces.size());
      node_leaf.data = &node_body.m_nodes[static_cast<int>(c->vertex)];
      face_leaf.data = &face_body.m_faces[static_cast<int>(c->triangle)];
      collide.Process(&node_leaf, &face_leaf);
    }
    if (contacts == ContactSet::NearestFace) counts.reduced = keepNearestFace(node_body, before, nullptr);
    counts.contacts = static_cast<std::size_t>(node_body.m_scontacts.size() - before);
    return counts;
  }
  const PairContext ctx{{&node_body, &face_body}, radius, motionTermFor(test, node_body, face_body)};
  std::vector<const btSoftBody::Node*> crossed;  // nodes with a crossing contact in this call
  std::vector<char> is_crossing;                 // per contact pushed in this call
  const auto take = [&](const btSoftBody::Node& node, ContactKind kind, const btSoftBody::SContact& contact) {
    if (kind == ContactKind::None) return;
    node_body.m_scontacts.push_back(contact);
    counts.robust += kind == ContactKind::Robust;
    if (test == ExactTest::Continuous) {
      is_crossing.push_back(kind == ContactKind::Crossing);
      if (kind == ContactKind::Crossing) {
        ++counts.crossings;
        crossed.push_back(&node);
      }
    }
  };
#if !defined(BT_USE_DOUBLE_PRECISION)
  if (lanes) {
    collideInLanes(test, ctx, node_body, face_body, first, last, take, counts.robust);
  } else
#endif
  {
    btSoftBody::SContact contact;
    for (const psc::CandidatePair* c = first; c != last; ++c) {
      assert(static_cast<int>(c->vertex) < node_body.m_nodes.size());
      assert(static_cast<int>(c->triangle) < face_body.m_faces.size());
      const btSoftBody::Node& node = node_body.m_nodes[static_cast<int>(c->vertex)];
      const btSoftBody::Face& face = face_body.m_faces[static_cast<int>(c->triangle)];
      take(node, test == ExactTest::Robust ? discreteTest(true, ctx, node, face, contact)
                                           : continuousTest(ctx, node, face, contact),
           contact);
    }
  }
  if (!crossed.empty()) {
    // A node that passed through a face of this body keeps its discrete contacts against the body,
    // but with the face's normal turned to the side the node started on: their closest-point
    // normals were decided from behind the surface and would push it further in. Dropping them
    // instead leaves the node guarded by the crossed face's plane alone, and where the surface is
    // folded (a dent under an impact) the solver then moves it through a neighbouring face.
    // Degenerate faces (no normal) lose the contact.
    std::sort(crossed.begin(), crossed.end());
    int out = before;
    for (int i = before; i < node_body.m_scontacts.size(); ++i) {
      btSoftBody::SContact& sc = node_body.m_scontacts[i];
      if (!is_crossing[static_cast<std::size_t>(i - before)] &&
          std::binary_search(crossed.begin(), crossed.end(), sc.m_node)) {
        const btSoftBody::Face& f = *sc.m_face;
        Vec3 n = faceNormal(toVec(f.m_n[0]->m_x), toVec(f.m_n[1]->m_x), toVec(f.m_n[2]->m_x));
        if (n == Vec3::Zero()) {
          ++counts.dropped;
          continue;
        }
        const std::array<double, 3> w{double(sc.m_weights.x()), double(sc.m_weights.y()), double(sc.m_weights.z())};
        if (n.dot(toVec(sc.m_node->m_q) - facePoint(f, w, true)) < 0.0) n = -n;
        sc.m_normal = toBt(n);
        ++counts.turned;
      }
      if (out != i) {
        node_body.m_scontacts[out] = sc;
        is_crossing[static_cast<std::size_t>(out - before)] = is_crossing[static_cast<std::size_t>(i - before)];
      }
      ++out;
    }
    node_body.m_scontacts.resize(out);
    is_crossing.resize(static_cast<std::size_t>(out - before));
  }
  if (contacts == ContactSet::NearestFace)
    counts.reduced = keepNearestFace(node_body, before, test == ExactTest::Continuous ? &is_crossing : nullptr);
  counts.contacts = static_cast<std::size_t>(node_body.m_scontacts.size() - before);
  return counts;
}

std::size_t shareBandWeights(btSoftBody& node_body, int from, btScalar radius, std::size_t above) {
  btAlignedObjectArray<btSoftBody::SContact>& list = node_body.m_scontacts;
  const std::size_t threshold = std::max<std::size_t>(above, 1);
  if (from >= list.size() || static_cast<std::size_t>(list.size() - from) <= threshold) return 0;
  // Per node (by index): first how many contacts it has in the range, then how many of them lie
  // in the band. A node's contacts are not consecutive (the core's candidates come by region and
  // chunk pair). Only a node with more than `threshold` contacts can have more in its band, and the
  // band's distances (which read the face's corners) are measured only for such nodes' contacts:
  // in most pairs no node has that many, and the first pass, which reads only the node pointers,
  // is all the cost.
  thread_local std::vector<int> count;
  thread_local std::vector<char> in_band;
  const auto nodes_in_body = static_cast<std::size_t>(node_body.m_nodes.size());
  if (count.size() < nodes_in_body) count.resize(nodes_in_body, 0);
  const btSoftBody::Node* nodes = &node_body.m_nodes[0];
  const auto nodeOf = [&](int i) { return static_cast<std::size_t>(list[i].m_node - nodes); };
  // threshold < the range's size, an int.
  const auto limit = static_cast<int>(threshold);
  bool crowded = false;
  for (int i = from; i < list.size(); ++i) crowded |= ++count[nodeOf(i)] > limit;
  std::size_t changed = 0;
  if (crowded) {
    // From here on count[n] < 0 for the nodes over the threshold: -(1 + their band contacts so far).
    in_band.assign(static_cast<std::size_t>(list.size() - from), 0);
    const btScalar radius2 = radius * radius;
    for (int i = from; i < list.size(); ++i) {
      int& k = count[nodeOf(i)];
      if (k > limit) k = -1;
      // A contact's m_margin is the radius it was accepted at: one made at the margins alone
      // (Continuous's crossing contacts) is never a band contact, wherever its node lies.
      if (k < 0 && list[i].m_margin > radius && contactDistance2(list[i]) >= radius2) {
        in_band[static_cast<std::size_t>(i - from)] = 1;
        --k;
      }
    }
    for (int i = from; i < list.size(); ++i) {
      if (!in_band[static_cast<std::size_t>(i - from)]) continue;
      const int band = -count[nodeOf(i)] - 1;
      if (band <= limit) continue;
      btSoftBody::SContact& c = list[i];
      c.m_cfm[0] /= btScalar(band);
      c.m_cfm[1] /= btScalar(band);
      ++changed;
    }
  }
  for (int i = from; i < list.size(); ++i) count[nodeOf(i)] = 0;
  return changed;
}

}  // namespace psc::bullet
