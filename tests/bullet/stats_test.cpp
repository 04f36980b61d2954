// The per-step statistics, and the once-per-step contract: one sensor step per simulation
// (sub)step, each (node, face) tested at most once per step.
#include "contact_check.h"
#include "psc/bullet/bullet.h"
#include "soft_world.h"

#include <gtest/gtest.h>

namespace {

using psc_test::Scene;

int softContacts(const btAlignedObjectArray<btSoftBody*>& bodies) {
  int n = 0;
  for (int i = 0; i < bodies.size(); ++i) n += bodies[i]->m_scontacts.size();
  return n;
}

TEST(Stats, DescribeTheStep) {
  psc_test::SoftWorld w(0);
  psc_test::buildScene(Scene::ThreeInARow, w);
  auto plugin = psc::bullet::install(w.world);
  EXPECT_EQ(plugin.stats().sensor_steps, 0u);
  std::size_t steps_with_contacts = 0;
  w.run(20, [&] {
    const psc::bullet::Stats& s = plugin.stats();
    EXPECT_TRUE(s.error.empty()) << s.error;
    EXPECT_EQ(s.bodies, 3u);
    EXPECT_EQ(s.skipped_bodies, 0u);
    EXPECT_EQ(s.particles, plugin.sensorWorld().particles().size());
    EXPECT_GE(s.particles, 3u);
    EXPECT_GE(s.rounds, 1);
    EXPECT_EQ(s.candidate_pairs, plugin.sensorWorld().lastResult().candidates.size());
    EXPECT_EQ(s.flagged_pairs, plugin.sensorWorld().lastResult().flagged.size());
    // Every candidate of a collided pair is tested once; here every candidate pair is collided.
    EXPECT_EQ(s.exact_tests, s.candidate_pairs);
    EXPECT_EQ(s.contacts, std::size_t(softContacts(w.world.getSoftBodyArray())));
    EXPECT_LE(s.contacts, s.exact_tests);
    EXPECT_EQ(s.fallback_pairs, 0u);
    EXPECT_GE(s.ms_sensor_step, 0.0);
    EXPECT_GE(s.ms_exact, 0.0);
    EXPECT_EQ(s.core.particles, s.particles);
    if (s.contacts > 0) ++steps_with_contacts;
  });
  EXPECT_EQ(plugin.stats().sensor_steps, 20u);
  EXPECT_GT(steps_with_contacts, 10u);
}

TEST(Stats, OneSensorStepPerInternalSubstep) {
  psc_test::SoftWorld w(0);
  psc_test::buildScene(Scene::HeadOn, w);
  auto plugin = psc::bullet::install(w.world);
  // 3 fixed substeps of 1/180 s in one call.
  w.world.stepSimulation(btScalar(1.0 / 60.0), 3, btScalar(1.0 / 180.0));
  EXPECT_EQ(plugin.stats().sensor_steps, 3u);
  // No substep due: nothing happens, nothing is stepped.
  w.world.stepSimulation(btScalar(1.0 / 1000.0), 3, btScalar(1.0 / 180.0));
  EXPECT_EQ(plugin.stats().sensor_steps, 3u);
}

TEST(Stats, ASecondDispatchInTheSameStepAddsNoContacts) {
  psc_test::SoftWorld w(0);
  psc_test::buildScene(Scene::HeadOn, w);
  auto plugin = psc::bullet::install(w.world);
  w.run(10);
  int first = 0, second = 0;
  w.run(1, [&] {
    first = softContacts(w.world.getSoftBodyArray());
    w.world.performDiscreteCollisionDetection();
    second = softContacts(w.world.getSoftBodyArray());
    const psc_test::ContactAudit audit = psc_test::auditContacts(w.world.getSoftBodyArray());
    EXPECT_EQ(audit.duplicates, 0u);
  });
  EXPECT_GT(first, 0);
  EXPECT_EQ(second, first);
  EXPECT_EQ(plugin.stats().sensor_steps, 11u);
}

TEST(Stats, SensorsStepEvenWhenNoSoftPairIsDispatched) {
  psc_test::SoftWorld w(0);
  w.addSoft(psc::makeSphere(0.5, 200).translate({-3, 0, 0}));
  w.addSoft(psc::makeSphere(0.5, 200).translate({3, 0, 0}));
  auto plugin = psc::bullet::install(w.world);
  w.run(4);
  EXPECT_EQ(plugin.stats().sensor_steps, 4u);
  EXPECT_EQ(plugin.stats().bodies, 2u);
  EXPECT_EQ(plugin.stats().body_pairs, 0u);
  EXPECT_EQ(plugin.stats().contacts, 0u);
}

}  // namespace
