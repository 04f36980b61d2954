// Outcomes a user sees: soft balls rest on each other with the plugin and sink through each other
// without soft-soft collision; soft-rigid and rigid-rigid behave exactly as without the plugin.
#include "ground_truth.h"
#include "psc/bullet/bullet.h"
#include "soft_world.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <optional>

namespace {

using psc_test::SoftParams;
using psc_test::SoftWorld;

psc_test::Vec3 toVec(const btVector3& v) { return {double(v.x()), double(v.y()), double(v.z())}; }

/// Solid angle of triangle abc seen from p (Van Oosterom and Strackee), for the winding number.
double solidAngle(const psc_test::Vec3& p, const psc_test::Vec3& a, const psc_test::Vec3& b, const psc_test::Vec3& c) {
  const psc_test::Vec3 x = a - p, y = b - p, z = c - p;
  const double lx = x.norm(), ly = y.norm(), lz = z.norm();
  const double numerator = x.dot(y.cross(z));
  const double denominator = lx * ly * lz + x.dot(y) * lz + y.dot(z) * lx + z.dot(x) * ly;
  return 2.0 * std::atan2(numerator, denominator);
}

/// Deepest point of `body`'s nodes inside the closed surface of `other` (0 when none is inside),
/// measured as the distance to other's surface: how far one sank into the other.
double deepestPenetration(const btSoftBody& body, const btSoftBody& other) {
  double deepest = 0.0;
  for (int i = 0; i < body.m_nodes.size(); ++i) {
    const psc_test::Vec3 p = toVec(body.m_nodes[i].m_x);
    double winding = 0.0, distance = 1e300;
    for (int f = 0; f < other.m_faces.size(); ++f) {
      const btSoftBody::Face& face = other.m_faces[f];
      const psc_test::Vec3 a = toVec(face.m_n[0]->m_x), b = toVec(face.m_n[1]->m_x), c = toVec(face.m_n[2]->m_x);
      winding += solidAngle(p, a, b, c);
      distance = std::min(distance, psc_test::pointTriangleDistance(p, a, b, c));
    }
    if (std::abs(winding) > 2.0 * 3.14159265358979323846) deepest = std::max(deepest, distance);
  }
  return deepest;
}

struct Stack {
  double separation = 0.0;   ///< centroid height of the upper ball above the lower one, m
  double lateral = 0.0;      ///< horizontal distance of the centroids, m
  double penetration = 0.0;  ///< deepest node of either ball inside the other, m
};

constexpr double kRadius = 0.5;

/// A static floor and four walls: a square well 1.1 m wide for balls of 1 m, so a stack cannot
/// simply roll apart (a ball on a ball is an unstable equilibrium, in Bullet's default path too).
void addWell(SoftWorld& w) {
  w.addBox({3, 0.5f, 3}, 0, {0, -0.5f, 0});
  w.addBox({0.1f, 1.5f, 0.75f}, 0, {0.65f, 1.5f, 0});
  w.addBox({0.1f, 1.5f, 0.75f}, 0, {-0.65f, 1.5f, 0});
  w.addBox({0.75f, 1.5f, 0.1f}, 0, {0, 1.5f, 0.65f});
  w.addBox({0.75f, 1.5f, 0.1f}, 0, {0, 1.5f, -0.65f});
}

enum class Pipeline { Plugin, PluginAhead, BulletDefault, NoSoftSoft };

/// A ball resting at the bottom of the well, a second one dropped onto it from 0.1 m above.
Stack dropBallOnBall(Pipeline pipeline) {
  SoftWorld w;
  addWell(w);
  SoftParams p;
  p.damping = 0.05;
  p.iterations = 10;
  p.vf_ss = pipeline != Pipeline::NoSoftSoft;
  btSoftBody* lower = w.addSoft(psc::makeSphere(kRadius, 300).translate({0, kRadius + 0.02, 0}), p);
  btSoftBody* upper = w.addSoft(psc::makeSphere(kRadius, 300).translate({0, 3 * kRadius + 0.15, 0}), p);
  std::optional<psc::bullet::Plugin> plugin;
  psc::bullet::Settings settings;
  if (pipeline == Pipeline::PluginAhead) settings.sensors.motion_bound = psc::MotionBound::Ahead;
  if (pipeline != Pipeline::BulletDefault) plugin = psc::bullet::install(w.world, settings);
  Stack worst;
  int step = 0;
  w.run(150, [&] {
    if (++step % 10 == 0)
      worst.penetration = std::max({worst.penetration, deepestPenetration(*upper, *lower),
                                    deepestPenetration(*lower, *upper)});
  });
  const btVector3 offset = psc_test::centroid(*upper) - psc_test::centroid(*lower);
  worst.separation = double(offset.y());
  worst.lateral = std::hypot(double(offset.x()), double(offset.z()));
  return worst;
}

TEST(Outcome, SoftBallsRestOnEachOtherWithThePlugin) {
  const Stack with = dropBallOnBall(Pipeline::Plugin);
  const Stack ahead = dropBallOnBall(Pipeline::PluginAhead);
  const Stack bullet = dropBallOnBall(Pipeline::BulletDefault);
  const Stack off = dropBallOnBall(Pipeline::NoSoftSoft);
  std::printf("ball on ball after 2.5 s (radius %.2f m, margins 0.02 m): centroid height difference / deepest "
              "node inside the other ball: plugin %.3f / %.3f m, plugin with MotionBound::Ahead %.3f / %.3f m, "
              "Bullet VF_SS %.3f / %.3f m, soft-soft off %.3f / %.3f m\n",
              kRadius, with.separation, with.penetration, ahead.separation, ahead.penetration, bullet.separation, bullet.penetration, off.separation,
              off.penetration);
  // Resting: both balls squash in the well, but the upper one stays on top, its centroid more than
  // 1.2 radii above the lower one's (2 radii undeformed; measured 1.7 with the plugin and 1.6 with
  // Bullet's default path). Vertex-face contacts alone cannot stop an edge slipping between two
  // nodes, so some nodes end inside the other ball in Bullet's own path too (measured 0.18 m there,
  // 0.09 m with the plugin in single precision; 0.167 and 0.168 in double).
  EXPECT_GT(with.separation, 1.2 * kRadius);
  EXPECT_LT(with.penetration, 0.4 * kRadius);
  // Bullet's own VF_SS path, the reference the plugin replaces, keeps the stack too, with deeper
  // nodes inside: the plugin must not do worse than it. The deepest node is one node that slipped
  // between two others, and where it ends is chaotic: with double-precision Bullet the plugin read
  // 0.109, 0.168 and 0.124 m for crowded_band 16, 32 (the default) and 64, against Bullet's 0.167,
  // so 2% (3 mm) is left for it.
  EXPECT_GT(bullet.separation, 1.2 * kRadius);
  EXPECT_LT(bullet.penetration, 0.5 * kRadius);
  EXPECT_LE(with.penetration, 1.02 * bullet.penetration);
  // MotionBound::Ahead drops the contacts of nodes that move sideways or away, which Radius keeps
  // (measured 0.106 m deep against Radius's 0.089): still no worse than Bullet's own path.
  EXPECT_GT(ahead.separation, 1.2 * kRadius);
  EXPECT_LE(ahead.penetration, bullet.penetration);
  // Without soft-soft collision the same drop ends with one ball inside the other.
  EXPECT_LT(off.separation, 0.2 * kRadius);
  EXPECT_GT(off.penetration, 0.5 * kRadius);
}

TEST(Outcome, SoftBallOnRigidBoxIsUnchangedByThePlugin) {
  auto run = [](bool with_plugin) {
    SoftWorld w;
    w.addBox({1, 0.25, 1}, 0, {0, 0.25, 0});
    btSoftBody* ball = w.addSoft(psc::makeSphere(kRadius, 300).translate({0, 0.5 + kRadius + 0.1, 0}));
    std::optional<psc::bullet::Plugin> plugin;
    if (with_plugin) plugin = psc::bullet::install(w.world);
    w.run(120);
    double lowest = 1e300;
    for (int i = 0; i < ball->m_nodes.size(); ++i) lowest = std::min(lowest, double(ball->m_nodes[i].m_x.y()));
    return std::make_pair(psc_test::positionHash(w.world.getSoftBodyArray()), lowest);
  };
  const auto with = run(true);
  const auto without = run(false);
  EXPECT_EQ(with.first, without.first) << "the plugin changed a soft-rigid trajectory";
  // Resting on the box top (y = 0.5); Bullet's SDF contact lets the lowest nodes sink a few cm.
  EXPECT_GT(with.second, 0.5 - 0.1);
  EXPECT_LT(with.second, 0.5 + 0.1);
}

TEST(Outcome, RigidBoxOnSoftBallIsUnchangedByThePlugin) {
  auto run = [](bool with_plugin) {
    SoftWorld w;
    addWell(w);
    btSoftBody* ball = w.addSoft(psc::makeSphere(kRadius, 300).translate({0, kRadius + 0.02, 0}));
    btRigidBody* box = w.addBox({0.4f, 0.2f, 0.4f}, 0.5, {0, 1.5f, 0});
    std::optional<psc::bullet::Plugin> plugin;
    if (with_plugin) plugin = psc::bullet::install(w.world);
    w.run(120);
    const btVector3 box_position = box->getWorldTransform().getOrigin();
    return std::make_tuple(psc_test::positionHash(w.world.getSoftBodyArray()), box_position,
                           double(psc_test::centroid(*ball).y()));
  };
  const auto with = run(true);
  const auto without = run(false);
  EXPECT_EQ(std::get<0>(with), std::get<0>(without)) << "the plugin changed a soft-rigid trajectory";
  EXPECT_EQ(std::get<1>(with), std::get<1>(without));
  // The box (0.4 m high) rests on the ball in the well: its bottom face stays above the ball's
  // centroid, far from the floor it would reach through the ball (centre at 0.2 m).
  const double box_y = double(std::get<1>(with).y());
  const double ball_y = std::get<2>(with);
  std::printf("box on ball: box centre %.3f m, ball centroid %.3f m\n", box_y, ball_y);
  EXPECT_GT(box_y - 0.2, ball_y);
  EXPECT_GT(box_y, 0.6);
}

TEST(Outcome, RigidBoxesAreUnchangedByThePlugin) {
  auto run = [](bool with_plugin) {
    SoftWorld w;
    w.addBox({3, 0.5, 3}, 0, {0, -0.5, 0});
    btRigidBody* lower = w.addBox({0.3f, 0.3f, 0.3f}, 1, {0, 0.35f, 0});
    btRigidBody* upper = w.addBox({0.2f, 0.2f, 0.2f}, 1, {0.05f, 1.0f, 0});
    std::optional<psc::bullet::Plugin> plugin;
    if (with_plugin) plugin = psc::bullet::install(w.world);
    w.run(90);
    return std::make_pair(lower->getWorldTransform().getOrigin(), upper->getWorldTransform().getOrigin());
  };
  const auto with = run(true);
  const auto without = run(false);
  EXPECT_EQ(with.first, without.first);
  EXPECT_EQ(with.second, without.second);
  EXPECT_GT(double(with.second.y()), double(with.first.y()) + 0.4);
}

}  // namespace
