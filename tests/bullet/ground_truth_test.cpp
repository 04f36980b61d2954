// The brute-force ground truth itself: the prefiltered truth against the unfiltered one, and a hit
// rate that shows the check bites (the exact distance is psc::testkit's, tested in
// tests/testkit_test.cpp).
#include "ground_truth.h"
#include "soft_world.h"

#include <gtest/gtest.h>

namespace {

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
