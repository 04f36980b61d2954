// The brute-force ground truth itself: the point-triangle distance against dense sampling, the
// prefiltered truth against the unfiltered one, and a hit rate that shows the check bites.
#include "ground_truth.h"
#include "soft_world.h"

#include <gtest/gtest.h>

#include <random>

namespace {

using psc_test::Vec3;

TEST(GroundTruth, PointTriangleDistanceMatchesDenseSampling) {
  std::mt19937 rng(12345);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  auto random = [&] { return Vec3(u(rng), u(rng), u(rng)); };
  int inside_face = 0;
  for (int trial = 0; trial < 300; ++trial) {
    const Vec3 a = random(), b = random(), c = random(), p = 1.5 * random();
    const Vec3 closest = psc_test::closestPointOnTriangle(p, a, b, c);
    const double d = (closest - p).norm();
    // The closest point lies on the triangle (barycentric coordinates in [0, 1], summing to 1).
    const Vec3 n = (b - a).cross(c - a);
    const double area = n.norm();
    const double wa = (b - closest).cross(c - closest).dot(n) / (area * area);
    const double wb = (c - closest).cross(a - closest).dot(n) / (area * area);
    const double wc = 1.0 - wa - wb;
    EXPECT_GE(std::min({wa, wb, wc}), -1e-9);
    EXPECT_NEAR((wa * a + wb * b + wc * c - closest).norm(), 0.0, 1e-9);
    if (std::min({wa, wb, wc}) > 1e-6) ++inside_face;
    // No sampled point of the triangle is closer.
    const int k = 40;
    for (int i = 0; i <= k; ++i)
      for (int j = 0; i + j <= k; ++j) {
        const Vec3 q = a + (b - a) * (double(i) / k) + (c - a) * (double(j) / k);
        EXPECT_GE((q - p).norm(), d - 1e-12);
      }
  }
  // Both the face region and the edge/vertex regions were exercised.
  EXPECT_GT(inside_face, 20);
  EXPECT_LT(inside_face, 280);
}

TEST(GroundTruth, PrefilterChangesNothing) {
  psc_test::SoftWorld w(0);
  psc_test::buildScene(psc_test::Scene::ThreeInARow, w);
  std::size_t strict = 0, full = 0;
  w.run(16, [&] {
    const auto& bodies = w.world.getSoftBodyArray();
    const psc_test::GroundTruth fast = psc_test::bruteForceContacts(bodies);
    const psc_test::GroundTruth slow = psc_test::bruteForceContactsNoPrefilter(bodies);
    EXPECT_EQ(fast.strict, slow.strict);
    EXPECT_EQ(fast.full, slow.full);
    EXPECT_EQ(fast.allowed, slow.allowed);
    strict += fast.strict.size();
    full += fast.full.size();
  });
  EXPECT_GT(strict, 100u);
  EXPECT_GT(full, strict);
}

TEST(GroundTruth, FoundContactsAreRecognised) {
  psc_test::SoftWorld w(0);
  psc_test::buildScene(psc_test::Scene::HeadOn, w);
  std::size_t found = 0;
  w.run(12, [&] {
    for (const psc_test::ContactKey& key : psc_test::foundContacts(w.world.getSoftBodyArray())) {
      EXPECT_GE(key.face_body, 0);
      EXPECT_NE(key.face_body, key.node_body);
      ++found;
    }
  });
  EXPECT_GT(found, 0u);
}

}  // namespace
