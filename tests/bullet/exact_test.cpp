// The exact tests of Settings::exact (psc/bullet/exact.h): Robust is Bullet's CollideVF_SS bit for
// bit wherever Bullet accepts, and the exact contact, at any scale, where Bullet refuses a small
// face; Continuous's crossing finder agrees with a brute-force root finder; the plugin with Robust
// finds contacts between fine meshes where Bullet finds none.
#include "../../bullet_plugin/src/vf_lanes.h"
#include "contact_check.h"
#include "ground_truth.h"
#include "psc/bullet/bullet.h"
#include "psc/error.h"
#include "soft_world.h"

#include <gtest/gtest.h>

#include <Eigen/Geometry>

#include <array>
#include <cmath>
#include <cstdio>
#include <limits>
#include <map>
#include <random>
#include <set>
#include <utility>
#include <vector>

#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wmaybe-uninitialized"
#include <BulletSoftBody/btSoftBodyInternals.h>
#pragma GCC diagnostic pop

namespace {

using psc::bullet::ContactKind;
using psc::bullet::ExactTest;
using Vec3 = psc::Vec3;

btVector3 toBt(const Vec3& v) { return btVector3(btScalar(v.x()), btScalar(v.y()), btScalar(v.z())); }
Vec3 toVec(const btVector3& v) { return {double(v.x()), double(v.y()), double(v.z())}; }

/// One node of one body against one face of another, positions set by hand.
struct PairRig {
  btSoftBodyWorldInfo info;
  btSoftBody node_body{&info, 1, nullptr, nullptr};
  btSoftBody face_body{&info, 3, nullptr, nullptr};

  PairRig() {
    face_body.appendFace(0, 1, 2);
    node_body.m_cfg.kDF = btScalar(0.3);
    face_body.m_cfg.kDF = btScalar(0.6);
    face_body.m_cfg.kSHR = btScalar(0.8);
  }
  btSoftBody::Node& node() { return node_body.m_nodes[0]; }
  btSoftBody::Face& face() { return face_body.m_faces[0]; }
  void setMargins(double node_margin, double face_margin) {
    node_body.getCollisionShape()->setMargin(btScalar(node_margin));
    face_body.getCollisionShape()->setMargin(btScalar(face_margin));
  }
  /// Bullet's own test on the pair: the contact CollideVF_SS pushes, if any.
  bool bullet(btSoftBody::SContact& out) {
    btSoftColliders::CollideVF_SS collide;
    collide.mrg = node_body.getCollisionShape()->getMargin() + face_body.getCollisionShape()->getMargin();
    collide.psb[0] = &node_body;
    collide.psb[1] = &face_body;
    btDbvtNode node_leaf{}, face_leaf{};
    node_leaf.data = &node();
    face_leaf.data = &face();
    node_body.m_scontacts.resize(0);
    collide.Process(&node_leaf, &face_leaf);
    if (node_body.m_scontacts.size() == 0) return false;
    out = node_body.m_scontacts[0];
    node_body.m_scontacts.resize(0);
    return true;
  }
  ContactKind run(ExactTest test, btSoftBody::SContact& out) {
    return psc::bullet::exactContact(test, node_body, node(), face_body, face(), out);
  }
  double radius() {
    return double(node_body.getCollisionShape()->getMargin() + face_body.getCollisionShape()->getMargin()) +
           2.0 * (toVec(node().m_x) - toVec(node().m_q)).norm();
  }
  double distance() {
    return psc_test::pointTriangleDistance(toVec(node().m_x), toVec(face().m_n[0]->m_x), toVec(face().m_n[1]->m_x),
                                           toVec(face().m_n[2]->m_x));
  }
};

Vec3 randomUnit(std::mt19937_64& rng) {
  std::normal_distribution<double> g(0.0, 1.0);
  Vec3 v(g(rng), g(rng), g(rng));
  return v.normalized();
}

/// A triangle of edges around `size`, a node within about the acceptance radius of it, moving.
void randomPair(PairRig& rig, std::mt19937_64& rng, double size, double margin) {
  std::uniform_real_distribution<double> u(0.0, 1.0);
  const Vec3 center = Vec3(u(rng) - 0.5, u(rng) - 0.5, u(rng) - 0.5) * 4.0 * size;
  for (int i = 0; i < 3; ++i) {
    rig.face_body.m_nodes[i].m_x = toBt(center + randomUnit(rng) * size * (0.3 + u(rng)));
    rig.face_body.m_nodes[i].m_q = rig.face_body.m_nodes[i].m_x - toBt(randomUnit(rng) * margin * u(rng));
    rig.face_body.m_nodes[i].m_im = u(rng) < 0.1 ? btScalar(0) : btScalar(0.5 + u(rng));
  }
  const Vec3 a = toVec(rig.face().m_n[0]->m_x), b = toVec(rig.face().m_n[1]->m_x), c = toVec(rig.face().m_n[2]->m_x);
  const Vec3 on = a + u(rng) * (b - a) + u(rng) * (c - a) * 0.8;
  rig.setMargins(margin * 0.5, margin * 0.5);
  const double motion = u(rng) < 0.3 ? 0.0 : margin * u(rng);
  rig.node().m_x = toBt(on + randomUnit(rng) * 2.0 * (margin + 2.0 * motion) * u(rng));
  rig.node().m_q = rig.node().m_x - toBt(randomUnit(rng) * motion);
  rig.node().m_im = u(rng) < 0.1 ? btScalar(0) : btScalar(0.5 + u(rng));
}

TEST(ExactTests, RobustIsBulletBitForBitWhereBulletAcceptsOnRandomPairs) {
  PairRig rig;
  std::mt19937_64 rng(20240610);
  std::size_t accepted = 0, refused = 0, rescued = 0;
  for (int i = 0; i < 200000; ++i) {
    randomPair(rig, rng, 0.3, 0.05);
    btSoftBody::SContact theirs{}, robust{}, replica{};
    const bool bullet = rig.bullet(theirs);
    const ContactKind kr = rig.run(ExactTest::Robust, robust);
    const ContactKind kb = rig.run(ExactTest::Bullet, replica);
    if (bullet) {
      ++accepted;
      ASSERT_EQ(kb, ContactKind::Bullet) << "pair " << i;
      ASSERT_EQ(kr, ContactKind::Bullet) << "pair " << i;
      ASSERT_TRUE(psc_test::sameContact(theirs, replica)) << "pair " << i;
      ASSERT_TRUE(psc_test::sameContact(theirs, robust)) << "pair " << i;
    } else {
      ++refused;
      ASSERT_EQ(kb, ContactKind::None) << "pair " << i;
      // Where Bullet refuses, Robust adds a contact only where Bullet's thresholds skipped a face
      // or an edge that holds the closest point, and only within the radius.
      if (kr != ContactKind::None) {
        ++rescued;
        ASSERT_EQ(kr, ContactKind::Robust);
        ASSERT_LT(rig.distance(), rig.radius() * (1.0 + 1e-5)) << "pair " << i;
        const btVector3 a = rig.face().m_n[0]->m_x, b = rig.face().m_n[1]->m_x, c = rig.face().m_n[2]->m_x;
        const bool small = !(btCross(b - a, c - a).length2() > SIMD_EPSILON) || !((b - a).length2() > SIMD_EPSILON) ||
                           !((c - b).length2() > SIMD_EPSILON) || !((a - c).length2() > SIMD_EPSILON);
        ASSERT_TRUE(small) << "pair " << i;
      } else {
        const bool massless = rig.node().m_im <= 0 && (rig.face().m_n[0]->m_im <= 0 || rig.face().m_n[1]->m_im <= 0 ||
                                                       rig.face().m_n[2]->m_im <= 0);
        ASSERT_TRUE(massless || rig.distance() > rig.radius() * (1.0 - 1e-5)) << "pair " << i;
      }
    }
  }
  std::printf("random pairs: %zu accepted by Bullet (all equal bit for bit), %zu refused, %zu of them found by "
              "Robust on faces Bullet's thresholds skip\n", accepted, refused, rescued);
  EXPECT_GT(accepted, 40000u);
  EXPECT_GT(refused, 40000u);
}

/// Many pairs in two bodies (node i of one against face i of the other), drawn like randomPair
/// at sizes from tiny (faces Bullet's threshold skips) to large, with degenerate faces, nodes
/// exactly on a face or a corner, and fixed nodes mixed in.
struct BatchRig {
  btSoftBodyWorldInfo info;
  btSoftBody node_body;
  btSoftBody face_body;
  std::vector<psc::CandidatePair> candidates;

  // Spread start positions: nodes all at the origin would make Bullet's node tree degenerate
  // (quadratic insertion).
  static std::vector<btVector3> spread(int n) {
    std::vector<btVector3> x(std::size_t(n), btVector3(0, 0, 0));
    for (int i = 0; i < n; ++i) x[std::size_t(i)] = btVector3(btScalar(i % 97), btScalar((i / 97) % 97), btScalar(i / 9409));
    return x;
  }
  explicit BatchRig(int pairs)
      : node_body(&info, pairs, spread(pairs).data(), nullptr), face_body(&info, 3 * pairs, spread(3 * pairs).data(), nullptr) {
    for (int i = 0; i < pairs; ++i) face_body.appendFace(3 * i, 3 * i + 1, 3 * i + 2);
    node_body.m_cfg.kDF = btScalar(0.3);
    node_body.m_cfg.kSHR = btScalar(0.9);
    face_body.m_cfg.kDF = btScalar(0.6);
    face_body.m_cfg.kSHR = btScalar(0.8);
    node_body.getCollisionShape()->setMargin(btScalar(0.025));
    face_body.getCollisionShape()->setMargin(btScalar(0.025));
    std::mt19937_64 rng(4711);
    std::uniform_real_distribution<double> u(0.0, 1.0);
    const double sizes[] = {0.002, 0.01, 0.05, 0.3, 2.0};
    PairRig one;
    for (int i = 0; i < pairs; ++i) {
      randomPair(one, rng, sizes[i % 5], 0.05);
      btSoftBody::Node* corner[3] = {&face_body.m_nodes[3 * i], &face_body.m_nodes[3 * i + 1], &face_body.m_nodes[3 * i + 2]};
      for (int k = 0; k < 3; ++k) {
        corner[k]->m_x = one.face_body.m_nodes[k].m_x;
        corner[k]->m_q = one.face_body.m_nodes[k].m_q;
        corner[k]->m_im = one.face_body.m_nodes[k].m_im;
      }
      btSoftBody::Node& node = node_body.m_nodes[i];
      node.m_x = one.node().m_x;
      node.m_q = one.node().m_q;
      node.m_im = one.node().m_im;
      const double kind = u(rng);
      if (kind < 0.04) {
        corner[2]->m_x = corner[1]->m_x;  // two corners in one place
      } else if (kind < 0.08) {
        corner[2]->m_x = corner[0]->m_x + (corner[1]->m_x - corner[0]->m_x) * btScalar(u(rng));  // collinear
      } else if (kind < 0.12) {
        node.m_x = (corner[0]->m_x + corner[1]->m_x + corner[2]->m_x) / btScalar(3);  // on the face
      } else if (kind < 0.14) {
        node.m_x = corner[int(u(rng) * 3) % 3]->m_x;  // on a corner
        node.m_q = node.m_x;
      }
      candidates.push_back({0, psc::Index(i), 1, psc::Index(i)});
    }
  }
  /// The contacts collideCandidates appends with the lanes on or off.
  std::vector<btSoftBody::SContact> run(ExactTest test, bool lanes, psc::bullet::ExactCounts& counts) {
    psc::bullet::detail::allowVfLanes(lanes);
    node_body.m_scontacts.resize(0);
    counts = psc::bullet::collideCandidates(test, node_body, face_body, candidates.data(),
                                            candidates.data() + candidates.size());
    psc::bullet::detail::allowVfLanes(true);
    std::vector<btSoftBody::SContact> out(node_body.m_scontacts.size());
    for (int i = 0; i < node_body.m_scontacts.size(); ++i) out[std::size_t(i)] = node_body.m_scontacts[i];
    return out;
  }
};

/// Equal length and every contact equal bit for bit; names the first that differs.
::testing::AssertionResult sameContacts(const std::vector<btSoftBody::SContact>& a,
                                        const std::vector<btSoftBody::SContact>& b) {
  if (a.size() != b.size()) return ::testing::AssertionFailure() << a.size() << " contacts against " << b.size();
  for (std::size_t i = 0; i < a.size(); ++i)
    if (!psc_test::sameContact(a[i], b[i])) return ::testing::AssertionFailure() << "contact " << i << " differs";
  return ::testing::AssertionSuccess();
}

TEST(ExactTests, LanesAreBulletsTestBitForBit) {
  // The exact stage runs Bullet's test eight pairs at a time with AVX (bullet_plugin/src/vf_lanes.h).
  // It must push the very contacts CollideVF_SS::Process pushes, in the same order, and Robust's
  // lanes must give what Robust gives pair by pair. 10,003 pairs: the last three run scalar.
  if (sizeof(btScalar) != sizeof(float)) GTEST_SKIP() << "the lanes serve single-precision Bullet only";
  psc::bullet::detail::allowVfLanes(true);
  if (!psc::bullet::detail::vfLanesEnabled()) GTEST_SKIP() << "no AVX on this processor";
  BatchRig rig(10003);
  psc::bullet::ExactCounts lanes_counts, scalar_counts;
  const auto lanes = rig.run(ExactTest::Bullet, true, lanes_counts);
  const auto scalar = rig.run(ExactTest::Bullet, false, scalar_counts);
  ASSERT_TRUE(sameContacts(lanes, scalar));
  // The scalar run is Process itself, pair by pair:
  btSoftColliders::CollideVF_SS collide;
  collide.mrg = btScalar(0.05);
  collide.psb[0] = &rig.node_body;
  collide.psb[1] = &rig.face_body;
  rig.node_body.m_scontacts.resize(0);
  for (const psc::CandidatePair& c : rig.candidates) {
    btDbvtNode node_leaf{}, face_leaf{};
    node_leaf.data = &rig.node_body.m_nodes[int(c.vertex)];
    face_leaf.data = &rig.face_body.m_faces[int(c.triangle)];
    collide.Process(&node_leaf, &face_leaf);
  }
  std::vector<btSoftBody::SContact> process(std::size_t(rig.node_body.m_scontacts.size()));
  for (std::size_t i = 0; i < process.size(); ++i) process[i] = rig.node_body.m_scontacts[int(i)];
  ASSERT_TRUE(sameContacts(lanes, process));
  EXPECT_GT(lanes.size(), 2000u);
  EXPECT_LT(lanes.size(), 8000u);

  const auto robust_lanes = rig.run(ExactTest::Robust, true, lanes_counts);
  const auto robust_scalar = rig.run(ExactTest::Robust, false, scalar_counts);
  ASSERT_TRUE(sameContacts(robust_lanes, robust_scalar)) << "Robust";
  EXPECT_EQ(lanes_counts.robust, scalar_counts.robust);
  EXPECT_GT(lanes_counts.robust, 100u);  // Robust's own lanes (small faces, nodes on a face) were exercised

  // Continuous: the lanes decide its discrete part (Robust's), the crossing test follows.
  const auto continuous_lanes = rig.run(ExactTest::Continuous, true, lanes_counts);
  const auto continuous_scalar = rig.run(ExactTest::Continuous, false, scalar_counts);
  ASSERT_TRUE(sameContacts(continuous_lanes, continuous_scalar)) << "Continuous";
  EXPECT_EQ(lanes_counts.robust, scalar_counts.robust);
  EXPECT_EQ(lanes_counts.crossings, scalar_counts.crossings);
  EXPECT_EQ(lanes_counts.turned, scalar_counts.turned);
  EXPECT_EQ(lanes_counts.dropped, scalar_counts.dropped);
  EXPECT_GT(lanes_counts.crossings, 50u);
  std::printf("lanes: %zu Bullet contacts, %zu Robust contacts, %zu Continuous contacts (%zu crossings) of %zu pairs, "
              "equal bit for bit\n", lanes.size(), robust_lanes.size(), continuous_lanes.size(), lanes_counts.crossings,
              rig.candidates.size());
}

TEST(ExactTests, RobustFindsTheExactContactOnSmallFacesAtAnyScale) {
  // The same configurations at scales 1e-3 .. 1e3: Robust decides as the exact distance does and
  // gives the same weights and normal at every scale; Bullet refuses the small faces.
  const double scales[] = {1e-3, 1e-2, 1e-1, 1.0, 1e1, 1e2, 1e3};
  std::mt19937_64 rng(77);
  std::size_t contacts = 0, bullet_refused_small = 0, robust_kind = 0;
  for (int i = 0; i < 3000; ++i) {
    PairRig unit;
    randomPair(unit, rng, 0.05, 0.01);  // faces of area ~1e-3 at scale 1
    const double unit_distance = unit.distance(), unit_radius = unit.radius();
    const bool near_boundary = std::abs(unit_distance - unit_radius) < 1e-4 * unit_radius;
    btSoftBody::SContact reference{};
    bool have_reference = false;
    for (double s : scales) {
      PairRig rig;
      for (int k = 0; k < 3; ++k) {
        rig.face_body.m_nodes[k].m_x = toBt(toVec(unit.face_body.m_nodes[k].m_x) * s);
        rig.face_body.m_nodes[k].m_q = toBt(toVec(unit.face_body.m_nodes[k].m_q) * s);
        rig.face_body.m_nodes[k].m_im = unit.face_body.m_nodes[k].m_im;
      }
      rig.node().m_x = toBt(toVec(unit.node().m_x) * s);
      rig.node().m_q = toBt(toVec(unit.node().m_q) * s);
      rig.node().m_im = unit.node().m_im;
      rig.setMargins(0.005 * s, 0.005 * s);
      const double d = rig.distance(), r = rig.radius();
      btSoftBody::SContact c{}, b{};
      const ContactKind kind = rig.run(ExactTest::Robust, c);
      const bool bullet = rig.bullet(b);
      const bool massless = rig.node().m_im <= 0 && (rig.face().m_n[0]->m_im <= 0 || rig.face().m_n[1]->m_im <= 0 ||
                                                     rig.face().m_n[2]->m_im <= 0);
      if (near_boundary || massless) continue;
      ASSERT_EQ(kind != ContactKind::None, d < r) << "scale " << s << " pair " << i << " d/r " << d / r;
      if (kind == ContactKind::None) continue;
      ++contacts;
      robust_kind += kind == ContactKind::Robust;
      const double area = 0.5 * (toVec(rig.face().m_n[1]->m_x) - toVec(rig.face().m_n[0]->m_x))
                                    .cross(toVec(rig.face().m_n[2]->m_x) - toVec(rig.face().m_n[0]->m_x))
                                    .norm();
      if (area < 1e-5) bullet_refused_small += !bullet;
      // The contact point is the closest point, the normal points from it to the node.
      const Vec3 point = toVec(c.m_face->m_n[0]->m_x) * double(c.m_weights.x()) +
                         toVec(c.m_face->m_n[1]->m_x) * double(c.m_weights.y()) +
                         toVec(c.m_face->m_n[2]->m_x) * double(c.m_weights.z());
      EXPECT_NEAR((toVec(rig.node().m_x) - point).norm(), d, 1e-4 * r) << "scale " << s;
      EXPECT_NEAR(double(c.m_normal.length()), 1.0, 1e-5);
      EXPECT_NEAR(double(c.m_margin), r, 1e-5 * r);
      if (!have_reference) {
        reference = c;
        have_reference = true;
      } else {
        for (int k = 0; k < 3; ++k) {
          EXPECT_NEAR(double(c.m_weights[k]), double(reference.m_weights[k]), 2e-3) << "scale " << s;
          EXPECT_NEAR(double(c.m_normal[k]), double(reference.m_normal[k]), 2e-3) << "scale " << s;
        }
        EXPECT_NEAR(double(c.m_cfm[0]), double(reference.m_cfm[0]), 1e-4);
        EXPECT_NEAR(double(c.m_cfm[1]), double(reference.m_cfm[1]), 1e-4);
        EXPECT_EQ(c.m_friction, reference.m_friction);
      }
    }
  }
  EXPECT_GT(contacts, 5000u);
  EXPECT_GT(bullet_refused_small, 1000u);  // the faces Bullet cannot see, found by Robust
  EXPECT_GT(robust_kind, 1000u);
}

TEST(ExactTests, RobustsSinglePrecisionContactIsTheExactOneToWithinItsRounding) {
  // Robust's own contact is computed in single precision relative to the node (robust_kernel.h),
  // the double path taking what single precision cannot hold. Against the exact closest point in
  // double (closestPointOnTriangle) of the same float positions, on small faces Bullet refuses, far
  // from the origin too (up to 300 units, where a float's step is 3e-5, six thousandths of the
  // faces' size): the contact point's weights lie within 2.5e-4 of the exact ones (the region
  // weights' rounding at kSingleThin, the worst a face left to single precision can have),
  // whatever the offset; the normal within 1e-3 of the direction from the exact point to the node
  // (which lies at least kSingleShort of the radius from its face there). Slivers (height 1e-4 of
  // the longest edge) go to the double path: their weights are the exact ones rounded to float.
  if (sizeof(btScalar) != sizeof(float)) GTEST_SKIP() << "double-precision Bullet keeps Robust in double";
  std::mt19937_64 rng(2039);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  double worst_point = 0.0, worst_normal = 0.0;
  std::size_t contacts = 0, slivers = 0;
  for (int i = 0; i < 6000; ++i) {
    PairRig rig;
    const double size = 0.005;
    randomPair(rig, rng, size, 0.01);
    const bool sliver = i % 6 == 5;
    if (sliver) {
      // The third corner 1e-4 of the edge ab off its line, the node above the sliver's inside
      // (where its weights are the worst conditioned).
      const Vec3 a = toVec(rig.face().m_n[0]->m_x), b = toVec(rig.face().m_n[1]->m_x);
      const Vec3 off = (b - a).cross(randomUnit(rng)).normalized() * 1e-4 * (b - a).norm();
      const Vec3 c = a + (0.2 + 0.6 * u(rng)) * (b - a) + off;
      rig.face_body.m_nodes[2].m_x = toBt(c);
      const Vec3 inside = (a + b + c) / 3.0, normal = (b - a).cross(c - a).normalized();
      rig.node().m_x = toBt(inside + normal * 0.004 * (u(rng) - 0.5));
      rig.node().m_q = rig.node().m_x;
    }
    const double offsets[] = {0.0, 10.0, 300.0};
    const Vec3 shift = randomUnit(rng) * offsets[i % 3];
    for (int k = 0; k < 3; ++k) rig.face_body.m_nodes[k].m_x = toBt(toVec(rig.face_body.m_nodes[k].m_x) + shift);
    rig.node().m_x = toBt(toVec(rig.node().m_x) + shift);
    rig.node().m_q = toBt(toVec(rig.node().m_q) + shift);
    btSoftBody::SContact contact{};
    const ContactKind kind = rig.run(ExactTest::Robust, contact);
    // The reference reads the positions back after the plugin's call (within this file the compiler
    // may carry a position's double value past its rounding to float into Bullet's vector).
    const Vec3 p = toVec(rig.node().m_x), a = toVec(rig.face().m_n[0]->m_x), b = toVec(rig.face().m_n[1]->m_x),
               c = toVec(rig.face().m_n[2]->m_x);
    const psc::bullet::ClosestPoint exact = psc::bullet::closestPointOnTriangle(p, a, b, c);
    const double r = rig.radius(), d = std::sqrt(exact.distance2);
    if (std::abs(d - r) < 1e-4 * r || d < 0.05 * r) continue;  // the decision's edge; a normal from elsewhere
    if (kind != ContactKind::Robust) continue;  // Bullet's own contact (bit for bit: other tests), or none
    ++contacts;
    slivers += sliver;
    // The weights (the point relative to the face: evaluated from the corners' coordinates, a
    // weight's float rounding alone moves it by 6e-8 of the coordinates).
    double point_error = 0.0;
    for (int k = 0; k < 3; ++k) point_error = std::max(point_error, std::abs(double(contact.m_weights[k]) - exact.weights[k]));
    worst_point = std::max(worst_point, point_error);
    EXPECT_LT(point_error, sliver ? 1e-6 : 2.5e-4) << (sliver ? "sliver " : "pair ") << i;
    const Vec3 q = a * exact.weights[0] + b * exact.weights[1] + c * exact.weights[2];
    const double normal_error = (toVec(contact.m_normal) - (p - q).normalized()).norm();
    worst_normal = std::max(worst_normal, normal_error);
    EXPECT_LT(normal_error, 1e-3) << "pair " << i << " distance / radius " << d / r;
  }
  std::printf("Robust's own contacts: %zu (%zu on slivers); worst weight error %.3g, worst normal error %.3g\n", contacts,
              slivers, worst_point, worst_normal);
  EXPECT_GT(contacts, 1500u);
  EXPECT_GT(slivers, 200u);
}

TEST(ExactTests, RobustsNormalHoldsWhenTheRadiusIsFarBelowTheFace) {
  // A review's finding (stop 46): the single-precision path left a pair to the double one only when
  // the node lay within a hundredth of the radius of its face, but the face point's rounding grows
  // with the face (up to 2.4e-4 of it), so with a radius of 1e-4 of the face the normal of a node
  // at a few per cent of the radius was 47° off. Faces Bullet refuses (0.02 across, heights
  // from 3.5% to 24% of it), radii from 1e-2 to 1e-5 of the face, the node over the inside at 2% to
  // 52% of the radius: the normal stays within 0.01 rad of the exact direction, computed in double
  // from the same float positions. With double-precision Bullet (which refuses only |cross|² ≤
  // DBL_EPSILON, and keeps Robust in double) the faces are 1e-4 across, so that Bullet refuses them
  // there too.
  std::mt19937_64 rng(4646);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  std::size_t contacts = 0;
  double worst = 0.0;
  for (double relative : {1e-2, 1e-3, 1e-4, 1e-5}) {
    for (int i = 0; i < 1500; ++i) {
      PairRig rig;
      const double L = sizeof(btScalar) == sizeof(float) ? 0.02 : 1e-4, h = L * (0.035 + 0.2 * u(rng));
      const Vec3 ex = randomUnit(rng), ey = randomUnit(rng).cross(ex).normalized();
      const Vec3 corners[3] = {Vec3::Zero(), ex * L, ex * (L * u(rng)) + ey * h};
      for (int k = 0; k < 3; ++k) {
        rig.face_body.m_nodes[k].m_x = rig.face_body.m_nodes[k].m_q = toBt(corners[k]);
        rig.face_body.m_nodes[k].m_im = 1;
      }
      const Vec3 a = toVec(rig.face().m_n[0]->m_x), b = toVec(rig.face().m_n[1]->m_x), c = toVec(rig.face().m_n[2]->m_x);
      const double radius = L * relative;
      rig.setMargins(radius / 2, radius / 2);
      double w1 = u(rng), w2 = u(rng);
      if (w1 + w2 > 1.0) w1 = 1.0 - w1, w2 = 1.0 - w2;
      const Vec3 over = a + w1 * (b - a) + w2 * (c - a) + (b - a).cross(c - a).normalized() * radius * (0.02 + 0.5 * u(rng));
      rig.node().m_x = rig.node().m_q = toBt(over);
      rig.node().m_im = 1;
      btSoftBody::SContact contact{};
      if (rig.run(ExactTest::Robust, contact) != ContactKind::Robust) continue;  // Bullet's own, or none
      const Vec3 p = toVec(rig.node().m_x);
      const psc::bullet::ClosestPoint exact = psc::bullet::closestPointOnTriangle(p, a, b, c);
      const Vec3 q = a * exact.weights[0] + b * exact.weights[1] + c * exact.weights[2];
      const double error = std::acos(std::min(1.0, toVec(contact.m_normal).normalized().dot((p - q).normalized())));
      worst = std::max(worst, error);
      ++contacts;
      EXPECT_LT(error, 0.01) << "radius " << relative << " of the face, pair " << i;
    }
  }
  std::printf("Robust's own contacts with radii far below their faces: %zu, worst normal error %.3g rad\n", contacts, worst);
  EXPECT_GT(contacts, 3000u);
}

TEST(ExactTests, APairWithANonFinitePositionHasNoContact) {
  // A review's finding (stop 46): an infinite corner sent Robust to its double path, which gave the
  // normal (1, -inf, nan); an infinite m_q made the radius infinite, and Bullet's test accepted the
  // pair with a point it never set (a zero normal, an infinite margin). Whatever the test, such a
  // pair now has no contact; the plugin never hands one over (a body with a non-finite node is
  // left out of the sensors: bullet.Bodies tests).
  const double inf = std::numeric_limits<double>::infinity(), nan = std::numeric_limits<double>::quiet_NaN();
  for (ExactTest test : {ExactTest::Bullet, ExactTest::Robust, ExactTest::Continuous}) {
    for (int what = 0; what < 4; ++what) {
      PairRig rig;
      rig.setMargins(0.01, 0.01);
      const Vec3 corners[3] = {{0, 0, 0}, {0.5, 0, 0}, {0, 0.5, 0}};
      for (int k = 0; k < 3; ++k) {
        rig.face_body.m_nodes[k].m_x = rig.face_body.m_nodes[k].m_q = toBt(corners[k]);
        rig.face_body.m_nodes[k].m_im = 1;
      }
      rig.node().m_x = rig.node().m_q = btVector3(btScalar(0.1), btScalar(0.1), btScalar(0.005));
      rig.node().m_im = 1;
      btSoftBody::SContact contact{};
      ASSERT_NE(rig.run(test, contact), ContactKind::None) << "the finite pair is a contact";
      switch (what) {
        case 0: rig.face_body.m_nodes[1].m_x.setY(btScalar(inf)); break;
        case 1: rig.node().m_q.setZ(btScalar(inf)); break;
        case 2: rig.face_body.m_nodes[2].m_q.setX(btScalar(nan)); break;
        default: rig.node().m_x.setX(btScalar(-inf)); break;
      }
      EXPECT_EQ(rig.run(test, contact), ContactKind::None) << psc::bullet::toString(test) << ", case " << what;
    }
  }
}

TEST(ExactTests, RobustGivesANodeOnTheFaceAFiniteNormal) {
  PairRig rig;
  rig.setMargins(0.01, 0.01);
  rig.face_body.m_nodes[0].m_x = rig.face_body.m_nodes[0].m_q = btVector3(0, 0, 0);
  rig.face_body.m_nodes[1].m_x = rig.face_body.m_nodes[1].m_q = btVector3(1, 0, 0);
  rig.face_body.m_nodes[2].m_x = rig.face_body.m_nodes[2].m_q = btVector3(0, 1, 0);
  rig.node().m_x = btVector3(0.25, 0.25, 0);  // exactly on the face, arriving from below
  rig.node().m_q = btVector3(btScalar(0.25), btScalar(0.25), btScalar(-0.01));
  btSoftBody::SContact bullet{}, robust{};
  ASSERT_TRUE(rig.bullet(bullet));
  EXPECT_TRUE(std::isnan(double(bullet.m_normal.z())));  // Bullet's 0/0
  ASSERT_EQ(rig.run(ExactTest::Robust, robust), ContactKind::Robust);
  EXPECT_EQ(robust.m_normal, btVector3(0, 0, -1));  // back towards where it came from
  EXPECT_TRUE(psc_test::sameContact(robust, robust));
  EXPECT_NEAR(double(robust.m_weights.x()), 0.5, 1e-6);
}

// --- Continuous: firstCrossing against a brute-force root finder -------------------------------

/// f(t) straight from the positions at t (not from the cubic's coefficients).
double coplanarity(const std::array<Vec3, 4>& s, const std::array<Vec3, 4>& e, double t) {
  std::array<Vec3, 4> p;
  for (int i = 0; i < 4; ++i) p[i] = s[i] + t * (e[i] - s[i]);
  return (p[2] - p[1]).cross(p[3] - p[1]).dot(p[0] - p[1]);
}

struct BruteCrossing {
  bool found = false;
  double t = 0.0;
  double inside_distance = 0.0;  ///< distance over the tolerance distance at the accepted/first root
  bool ambiguous = false;        ///< a root whose inside test is within a factor 10 of the tolerance
};

/// Dense sampling of f for sign changes, bisection of each, inside test at each root in order.
BruteCrossing bruteForce(const std::array<Vec3, 4>& s, const std::array<Vec3, 4>& e, int samples = 20000) {
  double scale = 0.0;
  for (double t : {0.0, 1.0})
    for (int i : {2, 3, 0}) {
      const Vec3 a = s[1] + t * (e[1] - s[1]), p = s[i] + t * (e[i] - s[i]);
      scale = std::max(scale, (p - a).norm());
    }
  const double zero = 64.0 * 2.22e-16 * scale * scale * scale;
  BruteCrossing out;
  const auto sign = [&](double f) { return f > zero ? 1 : (f < -zero ? -1 : 0); };
  const auto check = [&](double t) {
    std::array<Vec3, 4> p;
    for (int i = 0; i < 4; ++i) p[i] = s[i] + t * (e[i] - s[i]);
    const double reach = std::max({(p[2] - p[1]).norm(), (p[3] - p[2]).norm(), (p[1] - p[3]).norm()});
    const double d = psc_test::pointTriangleDistance(p[0], p[1], p[2], p[3]) / (psc::bullet::kCrossingTolerance * reach);
    if (d > 0.1 && d < 10.0) out.ambiguous = true;
    if (d <= 1.0 && !out.found) {
      out.found = true;
      out.t = t;
    }
  };
  int previous = sign(coplanarity(s, e, 0.0));
  double previous_t = 0.0;
  for (int k = 1; k <= samples && !out.found; ++k) {
    const double t = double(k) / samples;
    const int now = sign(coplanarity(s, e, t));
    if (now != 0 && previous != 0 && now != previous) {
      double lo = previous_t, hi = t;
      for (int it = 0; it < 80; ++it) {
        const double mid = 0.5 * (lo + hi);
        (sign(coplanarity(s, e, mid)) == previous ? lo : hi) = mid;
      }
      check(0.5 * (lo + hi));
    } else if (now == 0 && k == samples && previous != 0) {  // ends on the face, having had a side
      check(1.0);
    }
    if (now != 0) {
      previous = now;
      previous_t = t;
    }
  }
  return out;
}

void compareWithBruteForce(const std::array<Vec3, 4>& s, const std::array<Vec3, 4>& e, std::size_t& compared,
                           std::size_t& crossings, std::size_t& ambiguous, const char* what, int i) {
  const BruteCrossing brute = bruteForce(s, e);
  const std::optional<psc::bullet::Crossing> ours = psc::bullet::firstCrossing(s, e);
  if (brute.ambiguous) {
    ++ambiguous;
    return;
  }
  ++compared;
  ASSERT_EQ(ours.has_value(), brute.found) << what << " " << i << (brute.found ? " brute t=" : "") << brute.t;
  if (!ours) return;
  ++crossings;
  ASSERT_NEAR(ours->t, brute.t, 1e-6) << what << " " << i;  // a near-double root is ill-conditioned
  // The weights name the meeting point: the moving point itself, at t.
  const double t = ours->t;
  Vec3 on = Vec3::Zero();
  for (int k = 0; k < 3; ++k) on += ours->weights[k] * (s[k + 1] + t * (e[k + 1] - s[k + 1]));
  const Vec3 p = s[0] + t * (e[0] - s[0]);
  const double reach = (e[2] - e[1]).norm() + (s[2] - s[1]).norm() + (e[3] - e[1]).norm();
  ASSERT_LT((on - p).norm(), 1e-5 * reach) << what << " " << i;
  ASSERT_NEAR(ours->weights[0] + ours->weights[1] + ours->weights[2], 1.0, 1e-12);
}

std::array<Vec3, 4> randomPoints(std::mt19937_64& rng, double spread) {
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  std::array<Vec3, 4> p;
  for (Vec3& v : p) v = Vec3(u(rng), u(rng), u(rng)) * spread;
  return p;
}

TEST(ExactTests, FirstCrossingMatchesBruteForceOnRandomMotions) {
  std::mt19937_64 rng(4242);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  std::size_t compared = 0, crossings = 0, ambiguous = 0;
  for (int i = 0; i < 4000; ++i) {
    const double scale = std::pow(10.0, -3.0 + 6.0 * u(rng));
    std::array<Vec3, 4> s = randomPoints(rng, scale), e = s;
    s[0] *= 0.3;  // the point starts near the triangle
    const std::array<Vec3, 4> motion = randomPoints(rng, scale * (u(rng) < 0.5 ? 0.3 : 2.0));
    for (int k = 0; k < 4; ++k) e[k] += motion[k];
    compareWithBruteForce(s, e, compared, crossings, ambiguous, "random", i);
  }
  std::printf("firstCrossing random: %zu compared, %zu crossings, %zu ambiguous\n", compared, crossings, ambiguous);
  EXPECT_GT(crossings, 300u);
  EXPECT_LT(ambiguous, compared / 50);
}

TEST(ExactTests, FirstCrossingMatchesBruteForceOnGrazingAndCoplanarMotions) {
  std::mt19937_64 rng(99);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  std::size_t compared = 0, crossings = 0, ambiguous = 0, grazing_found = 0;
  for (int i = 0; i < 1500; ++i) {
    const double scale = std::pow(10.0, -3.0 + 6.0 * u(rng));
    std::array<Vec3, 4> s = randomPoints(rng, scale), e = s;
    const std::array<Vec3, 4> motion = randomPoints(rng, scale);
    for (int k = 1; k < 4; ++k) e[k] += motion[k];
    // Edge or vertex grazing: the point passes through a point of an edge (or a vertex) at t*.
    const double t_star = 0.05 + 0.9 * u(rng);
    const int edge = static_cast<int>(u(rng) * 3.0);
    const double along = u(rng) < 0.3 ? 0.0 : u(rng);
    const Vec3 a = s[1 + edge] + t_star * (e[1 + edge] - s[1 + edge]);
    const Vec3 b = s[1 + (edge + 1) % 3] + t_star * (e[1 + (edge + 1) % 3] - s[1 + (edge + 1) % 3]);
    const Vec3 hit = a + along * (b - a);
    const Vec3 velocity = randomPoints(rng, scale)[0];
    s[0] = hit - t_star * velocity;
    e[0] = hit + (1.0 - t_star) * velocity;
    const std::size_t before = crossings;
    compareWithBruteForce(s, e, compared, crossings, ambiguous, "grazing", i);
    grazing_found += crossings > before;
  }
  // Coplanar: all four points in one plane that moves; the point never changes side.
  for (int i = 0; i < 500; ++i) {
    const double scale = std::pow(10.0, -3.0 + 6.0 * u(rng));
    std::array<Vec3, 4> s, e;
    const Vec3 ex = randomUnit(rng), ey = randomUnit(rng).cross(ex).normalized();
    const Vec3 shift = randomPoints(rng, scale)[0];
    for (int k = 0; k < 4; ++k) {
      s[k] = (ex * (u(rng) - 0.5) + ey * (u(rng) - 0.5)) * scale;
      e[k] = (ex * (u(rng) - 0.5) + ey * (u(rng) - 0.5)) * scale + shift;
    }
    EXPECT_FALSE(psc::bullet::firstCrossing(s, e).has_value()) << "coplanar " << i;
    compareWithBruteForce(s, e, compared, crossings, ambiguous, "coplanar", i);
  }
  // Starts in the plane then leaves it: no side to leave, no crossing; ends in the plane: a crossing.
  for (int i = 0; i < 500; ++i) {
    const double scale = std::pow(10.0, -3.0 + 6.0 * u(rng));
    std::array<Vec3, 4> s = randomPoints(rng, scale), e = s;
    const Vec3 in_plane = s[1] + 0.3 * (s[2] - s[1]) + 0.3 * (s[3] - s[1]);
    const Vec3 off = randomPoints(rng, scale)[0];
    const bool starts = i % 2 == 0;
    if (starts) {
      s[0] = in_plane;
      e[0] = in_plane + off;
      EXPECT_FALSE(psc::bullet::firstCrossing(s, e).has_value()) << "starts in plane " << i;
    } else {
      e[0] = in_plane;
      s[0] = in_plane + off;
      const auto hit = psc::bullet::firstCrossing(s, e);
      ASSERT_TRUE(hit.has_value()) << "ends on the face " << i;
      EXPECT_NEAR(hit->t, 1.0, 1e-9);
    }
    compareWithBruteForce(s, e, compared, crossings, ambiguous, "touch", i);
  }
  std::printf("firstCrossing grazing/coplanar: %zu compared, %zu crossings (%zu grazing), %zu ambiguous\n", compared,
              crossings, grazing_found, ambiguous);
  EXPECT_GT(grazing_found, 1200u);  // a grazing path meets the edge (within the tolerance)
}

TEST(ExactTests, ContinuousPushesANodeThatPassedThroughBackToItsSide) {
  PairRig rig;
  rig.setMargins(0.01, 0.01);
  const btVector3 a(0, 0, 0), b(1, 0, 0), c(0, 1, 0);
  const auto place = [&](const btVector3& shift_start, const btVector3& node_start, const btVector3& node_end) {
    rig.face_body.m_nodes[0].m_x = a;
    rig.face_body.m_nodes[1].m_x = b;
    rig.face_body.m_nodes[2].m_x = c;
    for (int i = 0; i < 3; ++i) {
      rig.face_body.m_nodes[i].m_q = rig.face_body.m_nodes[i].m_x + shift_start;
      rig.face_body.m_nodes[i].m_im = 1;
    }
    rig.node().m_q = node_start;
    rig.node().m_x = node_end;
    rig.node().m_im = 1;
  };
  const btScalar quarter(0.25), tenth(btScalar(0.1));
  // 1. A node falls through a resting face: Bullet accepts it (its radius grows with the node's
  //    motion) but from behind, with a normal that points through the face.
  place({0, 0, 0}, {quarter, quarter, tenth}, {quarter, quarter, -tenth});
  btSoftBody::SContact bullet{}, robust{}, continuous{};
  ASSERT_TRUE(rig.bullet(bullet));
  EXPECT_LT(double(bullet.m_normal.z()), -0.99);
  ASSERT_EQ(rig.run(ExactTest::Continuous, continuous), ContactKind::Crossing);
  EXPECT_NEAR(double(continuous.m_normal.z()), 1.0, 1e-6);
  EXPECT_NEAR(double(continuous.m_weights.x()), 0.5, 1e-6);
  EXPECT_NEAR(double(continuous.m_weights.y()), 0.25, 1e-6);
  EXPECT_NEAR(double(continuous.m_weights.z()), 0.25, 1e-6);
  EXPECT_EQ(continuous.m_margin, btScalar(0.02));
  EXPECT_EQ(continuous.m_friction, bullet.m_friction);
  EXPECT_EQ(continuous.m_cfm[0], bullet.m_cfm[0]);
  // 2. A fast face sweeps over a resting node: Bullet's radius is the margins alone, it misses.
  place({0, 0, btScalar(-0.5)}, {quarter, quarter, btScalar(-0.2)}, {quarter, quarter, btScalar(-0.2)});
  EXPECT_FALSE(rig.bullet(bullet));
  EXPECT_EQ(rig.run(ExactTest::Robust, robust), ContactKind::None);
  ASSERT_EQ(rig.run(ExactTest::Continuous, continuous), ContactKind::Crossing);
  EXPECT_NEAR(double(continuous.m_normal.z()), 1.0, 1e-6);  // the node started above the face
  // 3. Passing beside the face, or approaching without crossing: Continuous is Robust, at
  //    Bullet's radius (margins + 2·|m_x − m_q|), contact for contact.
  place({0, 0, 0}, {btScalar(1.2), btScalar(1.2), tenth}, {btScalar(1.2), btScalar(1.2), -tenth});
  EXPECT_EQ(rig.run(ExactTest::Continuous, continuous), ContactKind::None);
  place({0, 0, 0}, {quarter, quarter, tenth}, {quarter, quarter, btScalar(0.005)});
  ASSERT_EQ(rig.run(ExactTest::Robust, robust), ContactKind::Bullet);
  ASSERT_EQ(rig.run(ExactTest::Continuous, continuous), ContactKind::Bullet);
  EXPECT_GT(robust.m_margin, btScalar(0.2)) << "Bullet's radius: margins + 2 * 0.095";
  EXPECT_TRUE(psc_test::sameContact(robust, continuous));
  // 4. Approaching, 0.05 from the face at the end: inside Bullet's radius, outside the margins.
  //    Until 2026-11-26 Continuous took the margins alone and made no contact here.
  place({0, 0, 0}, {quarter, quarter, tenth}, {quarter, quarter, btScalar(0.05)});
  EXPECT_EQ(rig.run(ExactTest::Robust, robust), ContactKind::Bullet);
  EXPECT_EQ(rig.run(ExactTest::Continuous, continuous), ContactKind::Bullet);
  EXPECT_TRUE(psc_test::sameContact(robust, continuous));
}

/// The signed side of point p relative to the triangle (a, b, c), in its own orientation, in long
/// double: the sign of ((b − a) × (c − a)) · (p − a).
int sideOf(const Vec3& p, const Vec3& a, const Vec3& b, const Vec3& c) {
  using L = long double;
  const L e1[3] = {L(b.x()) - L(a.x()), L(b.y()) - L(a.y()), L(b.z()) - L(a.z())};
  const L e2[3] = {L(c.x()) - L(a.x()), L(c.y()) - L(a.y()), L(c.z()) - L(a.z())};
  const L r[3] = {L(p.x()) - L(a.x()), L(p.y()) - L(a.y()), L(p.z()) - L(a.z())};
  const L f = (e1[1] * e2[2] - e1[2] * e2[1]) * r[0] + (e1[2] * e2[0] - e1[0] * e2[2]) * r[1] +
              (e1[0] * e2[1] - e1[1] * e2[0]) * r[2];
  return f > 0 ? 1 : f < 0 ? -1 : 0;
}

TEST(ExactTests, ContinuousGivesNoPushToANodeThatCameBackThroughTheFace) {
  // A review's finding (stop 46): a face 10 across tilts by 0.05 rad about the y axis during the
  // step while a node passes under it at a shallow angle, 0.03 above it at the start and 0.02 above
  // it at the end (each in the face's frame of its time): it dipped through the turning face and
  // came back through it. The crossing contact took its side from today's normal against
  // yesterday's positions, pointed down, and the solver pushed the node through the face.
  PairRig rig;
  rig.setMargins(0.01, 0.01);
  const double alpha = 0.05;
  const Vec3 tri[3] = {{-5, -5, 0}, {5, -5, 0}, {0, 5, 0}};
  for (int k = 0; k < 3; ++k) {
    rig.face_body.m_nodes[k].m_q = toBt(tri[k]);
    rig.face_body.m_nodes[k].m_x = toBt(Vec3(tri[k].x() * std::cos(alpha), tri[k].y(), -tri[k].x() * std::sin(alpha)));
    rig.face_body.m_nodes[k].m_im = 1;
  }
  rig.node().m_q = btVector3(-1, 0, btScalar(0.03));
  rig.node().m_x = btVector3(1, 0, btScalar(-0.03));
  rig.node().m_im = 1;
  const auto at = [&](bool start, int k) { return toVec(start ? rig.face().m_n[k]->m_q : rig.face().m_n[k]->m_x); };
  ASSERT_EQ(sideOf(toVec(rig.node().m_q), at(true, 0), at(true, 1), at(true, 2)), 1);
  ASSERT_EQ(sideOf(toVec(rig.node().m_x), at(false, 0), at(false, 1), at(false, 2)), 1);
  const auto hit = psc::bullet::firstCrossing({toVec(rig.node().m_q), at(true, 0), at(true, 1), at(true, 2)},
                                              {toVec(rig.node().m_x), at(false, 0), at(false, 1), at(false, 2)});
  ASSERT_TRUE(hit.has_value()) << "the node does pass through the face during the step";
  EXPECT_NEAR(hit->t, 0.5, 1e-6);
  EXPECT_EQ(hit->returns, 1) << "and back through it at t = 0.6";
  btSoftBody::SContact contact{};
  EXPECT_NE(rig.run(ExactTest::Continuous, contact), ContactKind::Crossing) << "it ends on its own side: no push";

  // Random faces turning by up to 0.4 rad, against a brute-force count of the node's passes through
  // the face (the coplanarity's sign changes at 4,000 steps of the motion, in long double, with the
  // node within 1e-6 of the face there): a node that passed through twice gets no crossing contact;
  // one that passed through once, never crossed the face's plane beside it and ends on the other
  // side gets one, towards the side it started on.
  std::mt19937_64 rng(46);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  std::size_t crossings = 0, back = 0;
  for (int i = 0; i < 12000; ++i) {
    const Eigen::Matrix3d rot = Eigen::AngleAxisd(0.4 * u(rng), randomUnit(rng)).toRotationMatrix();
    const Vec3 shift = 0.05 * Vec3(u(rng), u(rng), u(rng));
    for (int k = 0; k < 3; ++k) {
      const Vec3 corner = tri[k] * (0.2 + 0.1 * u(rng)) + 0.05 * Vec3(u(rng), u(rng), u(rng));
      rig.face_body.m_nodes[k].m_q = toBt(corner);
      rig.face_body.m_nodes[k].m_x = toBt(rot * corner + shift);
    }
    const Vec3 from(0.5 * u(rng), 0.5 * u(rng), 0.1 * u(rng));
    rig.node().m_q = toBt(from);
    rig.node().m_x = toBt(from + Vec3(0.6 * u(rng), 0.6 * u(rng), 0.15 * u(rng)));
    const std::array<Vec3, 4> s{toVec(rig.node().m_q), at(true, 0), at(true, 1), at(true, 2)};
    const std::array<Vec3, 4> e{toVec(rig.node().m_x), at(false, 0), at(false, 1), at(false, 2)};
    int inside = 0, beside = 0, unclear = 0;
    const auto lerp = [&](int k, double t) { return Vec3(s[k] + t * (e[k] - s[k])); };
    int previous = sideOf(s[0], s[1], s[2], s[3]);
    for (int step = 1; step <= 4000; ++step) {
      const double t = step / 4000.0;
      const int now = sideOf(lerp(0, t), lerp(1, t), lerp(2, t), lerp(3, t));
      if (now != 0 && previous != 0 && now != previous) {
        // Where the sign changed: the node's barycentric coordinates in the face's plane.
        const Vec3 a = lerp(1, t), ab = lerp(2, t) - a, ac = lerp(3, t) - a, ap = lerp(0, t) - a;
        const Vec3 n = ab.cross(ac);
        const double wb = ap.cross(ac).dot(n) / n.squaredNorm(), wc = ab.cross(ap).dot(n) / n.squaredNorm();
        const double least = std::min({1.0 - wb - wc, wb, wc});
        (least > 1e-3 ? inside : least < -1e-3 ? beside : unclear) += 1;
      }
      if (now != 0) previous = now;
    }
    if (unclear > 0) continue;
    const int start_side = sideOf(s[0], s[1], s[2], s[3]), end_side = sideOf(e[0], e[1], e[2], e[3]);
    const ContactKind kind = rig.run(ExactTest::Continuous, contact);
    if (inside == 2 && beside == 0) {
      ++back;
      EXPECT_NE(kind, ContactKind::Crossing) << "case " << i << ": came back through the face";
    } else if (inside == 1 && beside == 0 && start_side != 0 && end_side == -start_side) {
      ++crossings;
      ASSERT_EQ(kind, ContactKind::Crossing) << "case " << i;
      const Vec3 n_end = (e[2] - e[1]).cross(e[3] - e[1]).normalized();
      EXPECT_GT(toVec(contact.m_normal).dot(n_end) * start_side, 0.99) << "case " << i;
    }
  }
  std::printf("turning faces: %zu single crossings, %zu passes through and back\n", crossings, back);
  EXPECT_GT(crossings, 2000u);
  EXPECT_GT(back, 30u);
}

TEST(ExactTests, ContinuousTurnsTheDiscreteContactsOfACrossingNodeToItsSide) {
  // A folded surface (a dent): face 0 in the plane z = 0, face 1 rising from their shared edge
  // x = 0 towards −x. A node falls through face 0 and ends 0.27 from face 1 (within the margins),
  // nearest the shared edge, so face 1's closest-point normal points down, through the surface.
  btSoftBodyWorldInfo info;
  btSoftBody node_body{&info, 1, nullptr, nullptr};
  btSoftBody face_body{&info, 4, nullptr, nullptr};
  face_body.appendFace(0, 1, 2);
  face_body.appendFace(0, 3, 1);
  const btVector3 pos[] = {{0, 0, 0}, {0, 1, 0}, {1, 0.5, 0}, {-1, 0.5, 0.5}};
  for (int i = 0; i < 4; ++i) {
    face_body.m_nodes[i].m_x = face_body.m_nodes[i].m_q = pos[i];
    face_body.m_nodes[i].m_im = 1;
  }
  node_body.m_nodes[0].m_q = btVector3(btScalar(0.25), btScalar(0.4), btScalar(0.1));
  node_body.m_nodes[0].m_x = btVector3(btScalar(0.25), btScalar(0.4), btScalar(-0.1));
  node_body.m_nodes[0].m_im = 1;
  node_body.getCollisionShape()->setMargin(btScalar(0.2));
  face_body.getCollisionShape()->setMargin(btScalar(0.2));
  const psc::CandidatePair candidates[] = {{0, 0, 1, 0}, {0, 0, 1, 1}};
  // Each pair alone: a crossing of face 0; a discrete contact on face 1 whose normal points down.
  btSoftBody::SContact c0{}, c1{};
  ASSERT_EQ(psc::bullet::exactContact(ExactTest::Continuous, node_body, node_body.m_nodes[0], face_body,
                                      face_body.m_faces[0], c0),
            ContactKind::Crossing);
  ASSERT_NE(psc::bullet::exactContact(ExactTest::Continuous, node_body, node_body.m_nodes[0], face_body,
                                      face_body.m_faces[1], c1),
            ContactKind::None);
  EXPECT_LT(double(c1.m_normal.z()), 0.0);
  // Together: the crossing contact, and face 1's contact with its face normal on the node's side.
  const psc::bullet::ExactCounts n =
      psc::bullet::collideCandidates(ExactTest::Continuous, node_body, face_body, candidates, candidates + 2);
  EXPECT_EQ(n.tests, 2u);
  EXPECT_EQ(n.crossings, 1u);
  EXPECT_EQ(n.turned, 1u);
  EXPECT_EQ(n.dropped, 0u);
  ASSERT_EQ(n.contacts, 2u);
  ASSERT_EQ(node_body.m_scontacts.size(), 2);
  const btSoftBody::SContact& crossing = node_body.m_scontacts[0];
  const btSoftBody::SContact& turned = node_body.m_scontacts[1];
  EXPECT_EQ(crossing.m_face, &face_body.m_faces[0]);
  EXPECT_NEAR(double(crossing.m_normal.z()), 1.0, 1e-6);
  EXPECT_EQ(turned.m_face, &face_body.m_faces[1]);
  const Vec3 up = Vec3(0.5, 0.0, 1.0).normalized();  // face 1's normal, towards the node's start
  EXPECT_NEAR(double(turned.m_normal.x()), up.x(), 1e-6);
  EXPECT_NEAR(double(turned.m_normal.y()), up.y(), 1e-6);
  EXPECT_NEAR(double(turned.m_normal.z()), up.z(), 1e-6);
  // Everything else is the discrete contact's.
  btSoftBody::SContact expected = c1;
  expected.m_normal = turned.m_normal;
  EXPECT_TRUE(psc_test::sameContact(expected, turned));
}

// --- the plugin ---------------------------------------------------------------------------------

/// A jittered sheet of faces (spacing 0.05, margins 0.025 + 0.025) and nodes of another body over
/// and under it, each within the contact radius of a dozen faces or more; a third of the nodes
/// pass through the sheet during the step (m_q on one side, m_x on the other). The candidates are
/// every (node, face) pair, by face: the rig of ContactSet::NearestFace.
struct SheetRig {
  static constexpr int kSide = 16, kNodes = 300;
  btSoftBodyWorldInfo info;
  btSoftBody node_body;
  btSoftBody face_body;
  std::vector<psc::CandidatePair> candidates;

  static std::vector<btVector3> grid() {
    std::mt19937_64 rng(99);
    std::uniform_real_distribution<double> u(-1.0, 1.0);
    std::vector<btVector3> x;
    for (int i = 0; i < kSide; ++i)
      for (int k = 0; k < kSide; ++k)
        x.emplace_back(btScalar(0.05 * i), btScalar(0.008 * u(rng)), btScalar(0.05 * k));
    return x;
  }
  SheetRig() : node_body(&info, kNodes, BatchRig::spread(kNodes).data(), nullptr),
               face_body(&info, kSide * kSide, grid().data(), nullptr) {
    for (int i = 0; i + 1 < kSide; ++i)
      for (int k = 0; k + 1 < kSide; ++k) {
        const int a = i * kSide + k;
        face_body.appendFace(a, a + kSide, a + 1);
        face_body.appendFace(a + 1, a + kSide, a + kSide + 1);
      }
    for (int i = 0; i < face_body.m_nodes.size(); ++i) face_body.m_nodes[i].m_q = face_body.m_nodes[i].m_x;
    node_body.getCollisionShape()->setMargin(btScalar(0.025));
    face_body.getCollisionShape()->setMargin(btScalar(0.025));
    std::mt19937_64 rng(7);
    std::uniform_real_distribution<double> u(0.0, 1.0);
    for (int n = 0; n < kNodes; ++n) {
      btSoftBody::Node& node = node_body.m_nodes[n];
      const double x = 0.1 + 0.55 * u(rng), z = 0.1 + 0.55 * u(rng);
      if (n % 3 == 0) {  // through the sheet during the step
        node.m_q = btVector3(btScalar(x), btScalar(0.03 + 0.02 * u(rng)), btScalar(z));
        node.m_x = btVector3(btScalar(x + 0.01 * u(rng)), btScalar(-0.02 - 0.02 * u(rng)), btScalar(z));
      } else {
        node.m_x = btVector3(btScalar(x), btScalar(0.07 * (u(rng) - 0.3)), btScalar(z));
        node.m_q = node.m_x - btVector3(btScalar(0.004 * u(rng)), btScalar(0.004 * u(rng)), 0);
      }
      node.m_im = btScalar(1);
    }
    // Face by face: a node's candidates are not consecutive (nor are the core's, which come by
    // region and chunk pair).
    for (int f = 0; f < face_body.m_faces.size(); ++f)
      for (int n = 0; n < kNodes; ++n) candidates.push_back({0, psc::Index(n), 1, psc::Index(f)});
  }
  std::vector<btSoftBody::SContact> run(ExactTest test, psc::bullet::ContactSet set, psc::bullet::ExactCounts& counts) {
    node_body.m_scontacts.resize(0);
    counts = psc::bullet::collideCandidates(test, node_body, face_body, candidates.data(),
                                            candidates.data() + candidates.size(), set);
    std::vector<btSoftBody::SContact> out(std::size_t(node_body.m_scontacts.size()));
    for (int i = 0; i < node_body.m_scontacts.size(); ++i) out[std::size_t(i)] = node_body.m_scontacts[i];
    return out;
  }
};

/// The distance from a contact's node to its face point, in double (the reference for "nearest").
double contactDistance(const btSoftBody::SContact& c) {
  const btSoftBody::Face& f = *c.m_face;
  const Vec3 p = toVec(f.m_n[0]->m_x) * double(c.m_weights.x()) + toVec(f.m_n[1]->m_x) * double(c.m_weights.y()) +
                 toVec(f.m_n[2]->m_x) * double(c.m_weights.z());
  return (toVec(c.m_node->m_x) - p).norm();
}

/// Two soft spheres of radius 0.5 (800 vertices each, margins 0.05) meeting head-on at 1 unit/s each.
void addHeadOnSpheres(psc_test::SoftWorld& w) {
  psc_test::SoftParams p;
  p.margin = 0.05;
  w.addSoft(psc::makeSphere(0.5, 800).translate({-0.52, 0, 0}), p, {btScalar(1.0), 0, 0});
  w.addSoft(psc::makeSphere(0.5, 800).translate({0.52, 0.05, 0}), p, {btScalar(-1.0), 0, 0});
}

TEST(ExactTests, NearestFaceKeepsEachNodesNearestContactOfAllThoseAccepted) {
  // ContactSet::NearestFace against AllPairs on the same candidates: every node that got a contact
  // keeps exactly one discrete contact (plus, with Continuous, all its crossing contacts), it is
  // one of the node's AllPairs contacts bit for bit and the nearest of them (up to the float
  // rounding the reduction decides in), the kept contacts come in the same order, and
  // ExactCounts::reduced counts the rest.
  using psc::bullet::ContactSet;
  SheetRig rig;
  for (ExactTest test : {ExactTest::Bullet, ExactTest::Robust, ExactTest::Continuous}) {
    psc::bullet::ExactCounts all_counts, near_counts;
    const auto all = rig.run(test, ContactSet::AllPairs, all_counts);
    const auto near = rig.run(test, ContactSet::NearestFace, near_counts);
    const char* name = psc::bullet::toString(test);
    EXPECT_EQ(all_counts.reduced, 0u) << name;
    EXPECT_EQ(near_counts.reduced, all.size() - near.size()) << name;
    EXPECT_EQ(near_counts.crossings, all_counts.crossings) << name;
    EXPECT_EQ(near_counts.tests, all_counts.tests) << name;
    std::map<const btSoftBody::Node*, std::vector<std::size_t>> all_of, near_of;
    for (std::size_t i = 0; i < all.size(); ++i) all_of[all[i].m_node].push_back(i);
    for (std::size_t i = 0; i < near.size(); ++i) near_of[near[i].m_node].push_back(i);
    ASSERT_EQ(all_of.size(), near_of.size()) << name << ": no node may lose all its contacts";
    ASSERT_GT(all.size(), 4 * all_of.size()) << name << ": the rig must give nodes several contacts";
    // Kept contacts, in order: a subsequence of AllPairs' (bit for bit).
    std::size_t at = 0;
    for (const btSoftBody::SContact& c : near) {
      while (at < all.size() && !psc_test::sameContact(all[at], c)) ++at;
      ASSERT_LT(at, all.size()) << name << ": a kept contact is not one of AllPairs' in order";
      ++at;
    }
    for (const auto& [node, kept] : near_of) {
      const std::vector<std::size_t>& accepted = all_of[node];
      if (test != ExactTest::Continuous) {
        ASSERT_EQ(kept.size(), 1u) << name;
        double least = std::numeric_limits<double>::infinity();
        for (std::size_t i : accepted) least = std::min(least, contactDistance(all[i]));
        EXPECT_LE(contactDistance(near[kept[0]]), least * (1.0 + 1e-5) + 1e-7) << name << ": not the nearest";
      } else {
        EXPECT_GE(kept.size(), 1u);
        EXPECT_LE(kept.size(), accepted.size());
      }
    }
    if (test == ExactTest::Continuous) {
      EXPECT_GT(all_counts.crossings, 20u);
      // Every node keeps its crossings and at most one discrete contact.
      EXPECT_LE(near.size(), near_counts.crossings + near_of.size());
      EXPECT_GE(near.size(), near_of.size());
    }
    std::printf("nearest face, exact=%s: %zu nodes with contacts, %zu contacts of all pairs, %zu kept, %zu reduced, "
                "%zu crossings\n", name, all_of.size(), all.size(), near.size(), near_counts.reduced, near_counts.crossings);
  }
}

TEST(ExactTests, SharedBandWeightsDivideOnlyTheContactsBeyondTheMargins) {
  // shareBandWeights (Settings::runaway_sharing, `above` = 1, and Settings::crowded_band, larger
  // `above`) on the sheet's contacts with Bullet's and Robust's tests: the contacts whose node lies
  // within the margins stay as they were, bit for bit, and so do the band contacts of a node with
  // no more than `above` of them; each band contact of a node with more has its m_cfm divided by
  // how many its node has beyond the margins, so that they weigh one contact together; nothing else
  // changes, and the count returned is the number of contacts divided.
  SheetRig rig;
  const btScalar radius = rig.node_body.getCollisionShape()->getMargin() + rig.face_body.getCollisionShape()->getMargin();
  for (ExactTest test : {ExactTest::Bullet, ExactTest::Robust}) {
    std::size_t divided_by_all = 0;
    for (std::size_t above : {std::size_t{0}, std::size_t{1}, std::size_t{6}}) {
      const std::string name = std::string(psc::bullet::toString(test)) + ", above " + std::to_string(above);
      psc::bullet::ExactCounts counts;
      const std::vector<btSoftBody::SContact> before = rig.run(test, psc::bullet::ContactSet::AllPairs, counts);
      const std::size_t changed = psc::bullet::shareBandWeights(rig.node_body, 0, radius, above);
      ASSERT_EQ(std::size_t(rig.node_body.m_scontacts.size()), before.size()) << name << ": every contact stays";
      // The reference band: the node's distance to the face point at the contact's weights, in
      // float as the function measures it.
      const auto inBand = [&](const btSoftBody::SContact& c) { return psc_test::inBand(c, radius); };
      std::map<const btSoftBody::Node*, int> band;
      for (const btSoftBody::SContact& c : before) band[c.m_node] += inBand(c) ? 1 : 0;
      const int threshold = static_cast<int>(std::max<std::size_t>(above, 1));
      std::size_t divided = 0, kept = 0, kept_in_band = 0;
      for (std::size_t i = 0; i < before.size(); ++i) {
        const btSoftBody::SContact& was = before[i];
        const btSoftBody::SContact& now = rig.node_body.m_scontacts[int(i)];
        const int k = band[was.m_node];
        if (!inBand(was) || k <= threshold) {
          EXPECT_TRUE(psc_test::sameContact(was, now)) << name << ": contact " << i << " changed";
          ++kept;
          kept_in_band += inBand(was) ? 1 : 0;
          continue;
        }
        ++divided;
        EXPECT_EQ(now.m_cfm[0], was.m_cfm[0] / btScalar(k)) << name;
        EXPECT_EQ(now.m_cfm[1], was.m_cfm[1] / btScalar(k)) << name;
        EXPECT_TRUE(psc_test::sharedWeight(was, now, radius)) << name;
        // Everything but the weights as it was.
        btSoftBody::SContact restored = now;
        restored.m_cfm[0] = was.m_cfm[0];
        restored.m_cfm[1] = was.m_cfm[1];
        EXPECT_TRUE(psc_test::sameContact(was, restored)) << name;
      }
      EXPECT_EQ(changed, divided) << name;
      EXPECT_GT(kept, 0u) << name << ": and some within them";
      if (above <= 1) {
        EXPECT_GT(divided, 100u) << name << ": the rig must give nodes several contacts beyond the margins";
        divided_by_all = divided;
      } else {
        // The rig has nodes on both sides of the threshold.
        EXPECT_GT(divided, 0u) << name;
        EXPECT_GT(kept_in_band, 0u) << name;
        EXPECT_LT(divided, divided_by_all) << name;
      }
      std::printf("shared band weights, %s: %zu of %zu contacts divided\n", name.c_str(), divided, before.size());
      // Called again on what is left from `before`'s end: nothing to do.
      EXPECT_EQ(psc::bullet::shareBandWeights(rig.node_body, rig.node_body.m_scontacts.size(), radius, above), 0u) << name;
    }
  }
}

TEST(ExactTests, NearestFaceIsValidatedAndNamedInThePlugin) {
  // The plugin hands the setting to its exact stage (Stats::reduced_contacts) and still applies the
  // runaway rule to what the exact test accepted.
  EXPECT_STREQ(psc::bullet::toString(psc::bullet::ContactSet::AllPairs), "all");
  EXPECT_STREQ(psc::bullet::toString(psc::bullet::ContactSet::NearestFace), "nearest");
  for (psc::bullet::ContactSet set : {psc::bullet::ContactSet::AllPairs, psc::bullet::ContactSet::NearestFace}) {
    psc_test::SoftWorld w(0);
    addHeadOnSpheres(w);
    psc::bullet::Settings settings;
    settings.contacts = set;
    auto plugin = psc::bullet::install(w.world, settings);
    std::size_t contacts = 0, reduced = 0, duplicates = 0;
    w.run(20, [&] {
      contacts += plugin.stats().contacts;
      reduced += plugin.stats().reduced_contacts;
      for (btSoftBody* body : {w.world.getSoftBodyArray()[0], w.world.getSoftBodyArray()[1]}) {
        std::set<const void*> nodes;
        for (int i = 0; i < body->m_scontacts.size(); ++i) duplicates += !nodes.insert(body->m_scontacts[i].m_node).second;
      }
    });
    EXPECT_GT(contacts, 100u) << psc::bullet::toString(set);
    if (set == psc::bullet::ContactSet::AllPairs) {
      EXPECT_EQ(reduced, 0u);
      EXPECT_GT(duplicates, 0u) << "a resting node is within the radius of several faces";
    } else {
      EXPECT_GT(reduced, contacts) << "most accepted contacts are beside the nearest";
      EXPECT_EQ(duplicates, 0u) << "one contact per node and body it touches";
    }
  }
}

TEST(ExactTests, NearestFaceWithRobustTestsOnlyEachNodesNearestCandidates) {
  // With Robust, which accepts every pair within the radius, NearestFace lets the core hand over
  // only each node's nearest candidates (SensorSettings::nearest_candidates); Bullet's test, which
  // refuses small faces, gets them all. Where no face is small the two tests agree bit for bit, so
  // the two runs must make the very same contacts, step for step, from far fewer tests.
  const auto run = [](ExactTest exact, std::size_t& tests, std::size_t& not_nearest) {
    psc_test::SoftWorld w(0);
    addHeadOnSpheres(w);
    psc::bullet::Settings settings;
    settings.exact = exact;
    settings.contacts = psc::bullet::ContactSet::NearestFace;
    auto plugin = psc::bullet::install(w.world, settings);
    // Per step, each contact with its node and face as indices (the bodies differ between runs).
    std::vector<std::vector<std::pair<std::array<long, 2>, btSoftBody::SContact>>> contacts;
    tests = not_nearest = 0;
    w.run(20, [&] {
      tests += plugin.stats().exact_tests;
      not_nearest += plugin.stats().core.candidates_not_nearest;
      std::vector<std::pair<std::array<long, 2>, btSoftBody::SContact>> step;
      for (int k = 0; k < 2; ++k) {
        btSoftBody* body = w.world.getSoftBodyArray()[k];
        btSoftBody* other = w.world.getSoftBodyArray()[1 - k];
        for (int i = 0; i < body->m_scontacts.size(); ++i) {
          btSoftBody::SContact c = body->m_scontacts[i];
          const std::array<long, 2> at{long(c.m_node - &body->m_nodes[0]), long(c.m_face - &other->m_faces[0])};
          c.m_node = nullptr;
          c.m_face = nullptr;
          step.emplace_back(at, c);
        }
      }
      contacts.push_back(step);
    });
    return contacts;
  };
  std::size_t bullet_tests = 0, robust_tests = 0, bullet_not_nearest = 0, robust_not_nearest = 0;
  const auto bullet = run(ExactTest::Bullet, bullet_tests, bullet_not_nearest);
  const auto robust = run(ExactTest::Robust, robust_tests, robust_not_nearest);
  ASSERT_EQ(bullet.size(), robust.size());
  std::size_t total = 0;
  for (std::size_t s = 0; s < bullet.size(); ++s) {
    ASSERT_EQ(bullet[s].size(), robust[s].size()) << "step " << s;
    for (std::size_t i = 0; i < bullet[s].size(); ++i) {
      ASSERT_EQ(bullet[s][i].first, robust[s][i].first) << "step " << s << ", contact " << i;
      ASSERT_TRUE(psc_test::sameContact(bullet[s][i].second, robust[s][i].second)) << "step " << s << ", contact " << i;
    }
    total += bullet[s].size();
  }
  std::printf("nearest face: %zu contacts in both; exact tests %zu with Bullet's test, %zu with Robust (%zu candidates "
              "left out by the core)\n", total, bullet_tests, robust_tests, robust_not_nearest);
  EXPECT_GT(total, 100u);
  EXPECT_EQ(bullet_not_nearest, 0u);
  EXPECT_GT(robust_not_nearest, 0u);
  EXPECT_LT(3 * robust_tests, bullet_tests);
  EXPECT_LE(robust_tests + robust_not_nearest, bullet_tests);  // its probes skip some without measuring them
}

TEST(ExactTests, SettingsExactIsValidatedAndNamed) {
  psc_test::SoftWorld w(0);
  psc::bullet::Settings s;
  const auto expectRefused = [&](const std::string& what, const std::string& named) {
    try {
      auto plugin = psc::bullet::install(w.world, s);
      ADD_FAILURE() << "accepted " << what;
    } catch (const psc::Error& e) {
      EXPECT_EQ(e.code(), psc::ErrorCode::InvalidSettings);
      EXPECT_NE(std::string(e.what()).find(named), std::string::npos) << e.what();
    }
  };
  s.exact = static_cast<ExactTest>(7);
  expectRefused("an exact test that does not exist", "Settings::exact");
  // The swept bound, which Continuous may use, does not exist in the thesis's flag-only mode; the
  // radius bound does.
  s.exact = ExactTest::Continuous;
  s.sensors.flagging = psc::Flagging::Sensors;
  s.sensors.motion_bound = psc::MotionBound::Swept;
  expectRefused("the swept bound with the thesis's flag-only mode", "motion_bound = Swept");
  s.sensors.motion_bound = psc::MotionBound::Radius;
  EXPECT_NO_THROW(psc::bullet::install(w.world, s));
  for (ExactTest t : {ExactTest::Bullet, ExactTest::Robust, ExactTest::Continuous})
    EXPECT_EQ(psc::bullet::exactTestFromString(psc::bullet::toString(t)), t);
  EXPECT_THROW(psc::bullet::exactTestFromString("exact"), psc::Error);
}

/// Runs a scene with the plugin using `exact`, returning the position hash after `steps`.
std::size_t runScene(psc_test::Scene scene, ExactTest exact, int steps, std::size_t* robust_contacts = nullptr,
                     std::size_t* contacts = nullptr) {
  psc_test::SoftWorld w(psc_test::sceneGravity(scene));
  psc_test::buildScene(scene, w);
  psc::bullet::Settings settings;
  settings.exact = exact;
  auto plugin = psc::bullet::install(w.world, settings);
  w.run(steps, [&] {
    if (robust_contacts) *robust_contacts += plugin.stats().robust_contacts;
    if (contacts) *contacts += plugin.stats().contacts;
    // Real pairs: every contact Bullet's test accepts for its (node, face) is Bullet's own.
    if (exact == ExactTest::Robust) {
      const psc_test::ContactAudit audit = psc_test::auditContacts(w.world.getSoftBodyArray());
      EXPECT_EQ(audit.field_mismatches, 0u) << audit.first_problem;
      EXPECT_EQ(audit.outside_radius, 0u) << audit.first_problem;
    }
  });
  return psc_test::positionHash(w.world.getSoftBodyArray());
}

TEST(ExactTests, RobustRunsBitIdenticalToBulletWhereNoFaceIsSmall) {
  // Faces well above Bullet's threshold: every contact is Bullet's, so the whole simulation is
  // the same bit for bit.
  for (psc_test::Scene scene : {psc_test::Scene::HeadOn, psc_test::Scene::Concave}) {
    std::size_t robust = 0, contacts = 0;
    const std::size_t bullet_hash = runScene(scene, ExactTest::Bullet, 30);
    const std::size_t robust_hash = runScene(scene, ExactTest::Robust, 30, &robust, &contacts);
    EXPECT_EQ(bullet_hash, robust_hash) << psc_test::sceneName(scene);
    EXPECT_EQ(robust, 0u);
    EXPECT_GT(contacts, 500u) << psc_test::sceneName(scene);
  }
}

/// Nodes of one body that passed through a face of another during the last step (start → end of
/// the step, solver included) and ended it on the other side: firstCrossing over all pairs.
std::size_t tunnelledNodes(const std::vector<btSoftBody*>& bodies, const std::vector<std::vector<Vec3>>& before) {
  std::size_t count = 0;
  for (std::size_t a = 0; a < bodies.size(); ++a)
    for (int n = 0; n < bodies[a]->m_nodes.size(); ++n) {
      const Vec3 p0 = before[a][std::size_t(n)], p1 = toVec(bodies[a]->m_nodes[n].m_x);
      bool through = false;
      for (std::size_t b = 0; b < bodies.size() && !through; ++b) {
        if (a == b) continue;
        for (int f = 0; f < bodies[b]->m_faces.size() && !through; ++f) {
          const btSoftBody::Face& face = bodies[b]->m_faces[f];
          std::array<Vec3, 4> s, e;
          s[0] = p0;
          e[0] = p1;
          for (int k = 0; k < 3; ++k) {
            const int i = int(face.m_n[k] - &bodies[b]->m_nodes[0]);
            s[std::size_t(k + 1)] = before[b][std::size_t(i)];
            e[std::size_t(k + 1)] = toVec(face.m_n[k]->m_x);
          }
          const auto hit = psc::bullet::firstCrossing(s, e);
          if (!hit) continue;
          const Vec3 normal = (e[2] - e[1]).cross(e[3] - e[1]);
          Vec3 q0 = Vec3::Zero(), q1 = Vec3::Zero();
          for (int k = 0; k < 3; ++k) {
            q0 += hit->weights[std::size_t(k)] * s[std::size_t(k + 1)];
            q1 += hit->weights[std::size_t(k)] * e[std::size_t(k + 1)];
          }
          through = normal.dot(p0 - q0) * normal.dot(p1 - q1) < 0.0;
        }
      }
      count += through;
    }
  return count;
}

/// A cloth at 12 m/s (0.2 m a step) 0.19 m below a resting plate whose nodes cannot move: it
/// crosses the plate in the first step and ends it 1 cm beyond, inside every discrete radius
/// (margins 2 cm), so Bullet's test meets each pair from behind, with a normal along which the
/// node moves away: its solver applies no normal correction. Frictionless (Bullet's friction over
/// the hundreds of contacts its motion term gives a fast node stops it whatever the side).
/// The total of tunnelled nodes.
std::size_t clothThroughPlate(ExactTest exact, std::size_t* crossing_contacts) {
  psc_test::SoftWorld w(0);
  psc_test::SoftParams params;
  params.margin = 0.01;
  params.friction = 0.0;
  btSoftBody* plate = w.addSoft(psc::makePatch(1.0, 1.0, 10, 10), params);
  for (int i = 0; i < plate->m_nodes.size(); ++i) plate->setMass(i, 0);
  btSoftBody* cloth = w.addSoft(psc::makePatch(0.8, 0.8, 9, 9).translate({0.013, 0.021, -0.19}), params,
                                {0, 0, btScalar(12)});
  psc::bullet::Settings settings;
  settings.exact = exact;
  auto plugin = psc::bullet::install(w.world, settings);
  const std::vector<btSoftBody*> bodies{plate, cloth};
  std::size_t total = 0;
  for (int step = 0; step < 5; ++step) {
    std::vector<std::vector<Vec3>> before;
    for (btSoftBody* body : bodies) {
      before.emplace_back();
      for (int i = 0; i < body->m_nodes.size(); ++i) before.back().push_back(toVec(body->m_nodes[i].m_x));
    }
    w.step();
    *crossing_contacts += plugin.stats().crossing_contacts;
    const std::size_t through = tunnelledNodes(bodies, before);
    total += through;
  }
  return total;
}

TEST(ExactTests, ContinuousStopsNodesTunnellingWhereBulletsTestPushesThemThrough) {
  std::size_t crossings_bullet = 0, crossings_continuous = 0;
  const std::size_t bullet = clothThroughPlate(ExactTest::Bullet, &crossings_bullet);
  const std::size_t continuous = clothThroughPlate(ExactTest::Continuous, &crossings_continuous);
  std::printf("cloth through plate: tunnelled nodes over the run: bullet %zu, continuous %zu (%zu crossing "
              "contacts)\n", bullet, continuous, crossings_continuous);
  EXPECT_EQ(crossings_bullet, 0u);
  EXPECT_GT(bullet, 20u);
  EXPECT_GT(crossings_continuous, 10u);
  EXPECT_EQ(continuous, 0u);
}

/// Every (node, face) pair of different bodies within `radius(node)` of each other, in double, by
/// brute force over all faces (tests/bullet's ground truth leaves out the faces Bullet refuses).
struct TinyTruth {
  std::set<std::pair<const void*, const void*>> strict;  ///< distance < (1 − 1e-4) · margins
  std::set<std::pair<const void*, const void*>> full;    ///< distance < (1 + 1e-4) · Bullet's radius
};
TinyTruth tinyTruth(const btAlignedObjectArray<btSoftBody*>& bodies) {
  TinyTruth truth;
  for (int a = 0; a < bodies.size(); ++a)
    for (int b = 0; b < bodies.size(); ++b) {
      if (a == b) continue;
      const btSoftBody& A = *bodies[a];
      const btSoftBody& B = *bodies[b];
      const double margins = double(A.getCollisionShape()->getMargin() + B.getCollisionShape()->getMargin());
      for (int f = 0; f < B.m_faces.size(); ++f) {
        const btSoftBody::Face& face = B.m_faces[f];
        const Vec3 p0 = toVec(face.m_n[0]->m_x), p1 = toVec(face.m_n[1]->m_x), p2 = toVec(face.m_n[2]->m_x);
        const Vec3 lo = p0.cwiseMin(p1).cwiseMin(p2), hi = p0.cwiseMax(p1).cwiseMax(p2);
        for (int n = 0; n < A.m_nodes.size(); ++n) {
          const btSoftBody::Node& node = A.m_nodes[n];
          const Vec3 x = toVec(node.m_x);
          const double full = (margins + 2.0 * (x - toVec(node.m_q)).norm()) * (1.0 + 1e-4);
          if (((lo - x).cwiseMax(x - hi).array() > full).any()) continue;
          const double d = psc_test::pointTriangleDistance(x, p0, p1, p2);
          if (d < full) truth.full.insert({&node, &face});
          if (d < margins * (1.0 - 1e-4)) truth.strict.insert({&node, &face});
        }
      }
    }
  return truth;
}

TEST(ExactTests, RobustFindsContactsBetweenTinyTrianglesWhereBulletFindsNone) {
  // Two spheres of radius 0.05 m with ~2,000 vertices each: faces of ~8e-6 m², all below
  // Bullet's threshold. Bullet's test gets no contact; Robust gets every contact within the
  // margins and none outside Bullet's radius.
  for (ExactTest exact : {ExactTest::Bullet, ExactTest::Robust}) {
    psc_test::SoftWorld w(0);
    psc_test::SoftParams p;
    p.margin = 0.002;
    w.addSoft(psc::makeSphere(0.05, 2000).translate({-0.053, 0, 0}), p, {btScalar(0.3), 0, 0});
    w.addSoft(psc::makeSphere(0.05, 2000).translate({0.053, 0.005, 0}), p, {btScalar(-0.3), 0, 0});
    psc::bullet::Settings settings;
    settings.exact = exact;
    auto plugin = psc::bullet::install(w.world, settings);
    std::size_t contacts = 0, robust = 0, tests = 0, truth_strict = 0, found_strict = 0, outside = 0;
    w.run(12, [&] {
      contacts += plugin.stats().contacts;
      robust += plugin.stats().robust_contacts;
      tests += plugin.stats().exact_tests;
      const TinyTruth truth = tinyTruth(w.world.getSoftBodyArray());
      std::set<std::pair<const void*, const void*>> found;
      for (btSoftBody* body : {w.world.getSoftBodyArray()[0], w.world.getSoftBodyArray()[1]})
        for (int i = 0; i < body->m_scontacts.size(); ++i)
          found.insert({body->m_scontacts[i].m_node, body->m_scontacts[i].m_face});
      for (const auto& k : found) outside += truth.full.count(k) == 0;
      truth_strict += truth.strict.size();
      for (const auto& k : truth.strict) found_strict += found.count(k);
    });
    std::printf("tiny spheres, exact=%s: %zu tests, %zu contacts (%zu robust), strict truth %zu, found %zu\n",
                psc::bullet::toString(exact), tests, contacts, robust, truth_strict, found_strict);
    EXPECT_GT(tests, 1000u);
    EXPECT_GT(truth_strict, 100u);
    EXPECT_EQ(outside, 0u);
    // Double-precision Bullet's threshold (DBL_EPSILON) is far below these faces: it sees them.
    const bool below_bullets_threshold = sizeof(btScalar) == sizeof(float);
    if (exact == ExactTest::Bullet && below_bullets_threshold) {
      EXPECT_EQ(contacts, 0u);
    } else {
      EXPECT_GT(contacts, 100u);
      if (exact == ExactTest::Robust) {
        EXPECT_EQ(robust, below_bullets_threshold ? contacts : 0u);
      }
      EXPECT_EQ(found_strict, truth_strict);  // strict recall 1 over all pairs
    }
  }
}

}  // namespace
