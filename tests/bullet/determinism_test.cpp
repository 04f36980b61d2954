// The plugin is deterministic bit for bit: the same scene run twice in one process gives the same
// node positions after every step, and the same per-step counters.
#include "psc/bullet/bullet.h"
#include "soft_world.h"

#include <gtest/gtest.h>

#include <vector>

namespace {

using psc_test::Scene;

struct Trace {
  std::vector<std::size_t> hashes;    ///< node positions (bit patterns) after each step
  std::vector<std::size_t> contacts;  ///< plugin contacts of each step
  std::vector<std::size_t> exact_tests;
};

Trace run(Scene scene, int steps) {
  psc_test::SoftWorld w(psc_test::sceneGravity(scene));
  psc_test::buildScene(scene, w);
  auto plugin = psc::bullet::install(w.world);
  Trace trace;
  for (int s = 0; s < steps; ++s) {
    w.step();
    EXPECT_TRUE(plugin.stats().error.empty()) << plugin.stats().error;
    trace.hashes.push_back(psc_test::positionHash(w.world.getSoftBodyArray()));
    trace.contacts.push_back(plugin.stats().contacts);
    trace.exact_tests.push_back(plugin.stats().exact_tests);
  }
  return trace;
}

TEST(Determinism, PluginRunTwiceGivesBitIdenticalNodePositions) {
  // The pile: seven bodies, a floor, settling contacts, and a repartition on the way.
  constexpr int kSteps = 120;
  const Trace first = run(Scene::Pile, kSteps);
  const Trace second = run(Scene::Pile, kSteps);
  std::size_t contacts = 0;
  for (std::size_t c : first.contacts) contacts += c;
  EXPECT_GT(contacts, 10000u) << "the bodies must touch, or the comparison proves little";
  // The trajectory moves: a hash that never changes would make the comparison vacuous.
  EXPECT_NE(first.hashes.front(), first.hashes.back());
  for (int s = 0; s < kSteps; ++s) {
    ASSERT_EQ(first.hashes[std::size_t(s)], second.hashes[std::size_t(s)]) << "positions differ after step " << s + 1;
    ASSERT_EQ(first.contacts[std::size_t(s)], second.contacts[std::size_t(s)]) << "step " << s + 1;
    ASSERT_EQ(first.exact_tests[std::size_t(s)], second.exact_tests[std::size_t(s)]) << "step " << s + 1;
  }
}

}  // namespace
