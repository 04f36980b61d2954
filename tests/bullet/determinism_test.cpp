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
  std::vector<std::size_t> refit_after_predict;  ///< bodies refit right after their predictMotion
  std::vector<std::size_t> bodies;               ///< bodies the sensors held
};

/// `refit_after_predict`: the world's soft-body solver is psc::bullet::SoftBodySolver, attached to
/// the plugin, which then refits each body right after its predictMotion.
Trace run(Scene scene, int steps, bool refit_after_predict = false) {
  psc_test::SoftWorld w(psc_test::sceneGravity(scene), {}, refit_after_predict);
  psc_test::buildScene(scene, w);
  auto plugin = psc::bullet::install(w.world);
  if (refit_after_predict) plugin.attach(w.soft_solver);
  Trace trace;
  for (int s = 0; s < steps; ++s) {
    w.step();
    EXPECT_TRUE(plugin.stats().error.empty()) << plugin.stats().error;
    trace.refit_after_predict.push_back(plugin.stats().refit_after_predict);
    trace.bodies.push_back(plugin.stats().bodies);
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

TEST(Determinism, RefitAfterPredictMotionChangesNothing) {
  // psc::bullet::SoftBodySolver moves each body's refit from the sensor step to right after its
  // predictMotion. The pile repartitions on the way, and repartition checks ride on the refit:
  // positions, contacts and exact tests must stay the same bits, step by step.
  constexpr int kSteps = 120;
  const Trace in_step = run(Scene::Pile, kSteps);
  const Trace after_predict = run(Scene::Pile, kSteps, true);
  std::size_t refits = 0, held = 0;
  for (int s = 0; s < kSteps; ++s) {
    ASSERT_EQ(in_step.hashes[std::size_t(s)], after_predict.hashes[std::size_t(s)]) << "positions differ after step " << s + 1;
    ASSERT_EQ(in_step.contacts[std::size_t(s)], after_predict.contacts[std::size_t(s)]) << "step " << s + 1;
    ASSERT_EQ(in_step.exact_tests[std::size_t(s)], after_predict.exact_tests[std::size_t(s)]) << "step " << s + 1;
    EXPECT_EQ(in_step.refit_after_predict[std::size_t(s)], 0u);
    refits += after_predict.refit_after_predict[std::size_t(s)];
    held += after_predict.bodies[std::size_t(s)];
  }
  // The first step adds and partitions the bodies (the sensor step refits them); from then on every
  // body the sensors hold is refit after its predictMotion, unless a body sleeps.
  EXPECT_GT(refits, held * 9 / 10) << "refits after predictMotion: " << refits << " of " << held;
}

TEST(Determinism, SoftBodySolverDetachesFromItsPlugin) {
  psc_test::SoftWorld w(0.0, {}, true);
  psc_test::buildScene(Scene::HeadOn, w);
  {
    auto plugin = psc::bullet::install(w.world);
    plugin.attach(w.soft_solver);
    EXPECT_TRUE(w.soft_solver.attached());
    w.step();
    w.step();
    EXPECT_GT(plugin.stats().refit_after_predict, 0u);
  }
  EXPECT_FALSE(w.soft_solver.attached()) << "the destroyed plugin must not be called";
  w.step();  // Bullet's default behaviour, no plugin
  auto again = psc::bullet::install(w.world);
  again.attach(w.soft_solver);
  again.uninstall();
  EXPECT_FALSE(w.soft_solver.attached());
  w.step();
}

}  // namespace
