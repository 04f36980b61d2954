// The per-step statistics, and the once-per-step contract: one sensor step per simulation
// (sub)step, each (node, face) tested at most once per step.
#include "contact_check.h"
#include "psc/bullet/bullet.h"
#include "soft_world.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <optional>
#include <set>
#include <tuple>
#include <vector>

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
  const auto& bodies = w.world.getSoftBodyArray();
  std::size_t steps_with_contacts = 0;
  for (std::uint64_t step = 1; step <= 20; ++step) {
    std::size_t contacts = 0;
    std::size_t contacts_outside_candidates = 0;
    const auto start = std::chrono::steady_clock::now();
    w.run(1, [&] {
      contacts = std::size_t(softContacts(bodies));
      // Every contact of the step comes from one of this step's candidate pairs.
      std::set<std::tuple<psc::BodyId, psc::Index, psc::BodyId, psc::Index>> candidates;
      for (const psc::CandidatePair& c : plugin.sensorWorld().lastResult().candidates)
        candidates.insert({c.vertex_body, c.vertex, c.triangle_body, c.triangle});
      for (int b = 0; b < bodies.size(); ++b)
        for (int i = 0; i < bodies[b]->m_scontacts.size(); ++i) {
          const btSoftBody::SContact& c = bodies[b]->m_scontacts[i];
          const std::optional<psc::BodyId> node_body = plugin.bodyId(bodies[b]);
          std::optional<psc::BodyId> face_body;
          psc::Index face = 0;
          for (int o = 0; o < bodies.size(); ++o) {
            const btSoftBody& other = *bodies[o];
            if (other.m_faces.size() > 0 && c.m_face >= &other.m_faces[0] &&
                c.m_face < &other.m_faces[0] + other.m_faces.size()) {
              face_body = plugin.bodyId(&other);
              face = psc::Index(c.m_face - &other.m_faces[0]);
            }
          }
          const psc::Index node = psc::Index(c.m_node - &bodies[b]->m_nodes[0]);
          if (!node_body || !face_body || candidates.count({*node_body, node, *face_body, face}) == 0)
            ++contacts_outside_candidates;
        }
    });
    const double wall_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
    const psc::bullet::Stats& s = plugin.stats();
    EXPECT_TRUE(s.error.empty()) << s.error;
    EXPECT_EQ(s.sensor_steps, step) << "one sensor step per simulation step, counted once";
    EXPECT_EQ(s.bodies, 3u);
    EXPECT_EQ(s.skipped_bodies, 0u);
    EXPECT_EQ(s.core.bodies, s.bodies) << "the core holds exactly the bodies the plugin registered";
    // Each sphere is one convex part and two other parts can touch it: min(12, 2) = 2 particles each.
    EXPECT_EQ(s.particles, 6u);
    EXPECT_GE(s.rounds, 1);
    EXPECT_EQ(s.round_cap_hits, 0u);
    // Every candidate of a collided pair is tested once; here every candidate pair is collided.
    EXPECT_EQ(s.exact_tests, s.candidate_pairs);
    EXPECT_EQ(s.contacts, contacts) << "counted by the plugin vs found in m_scontacts";
    EXPECT_EQ(contacts_outside_candidates, 0u);
    EXPECT_LE(s.contacts, s.exact_tests);
    if (s.contacts > 0) {
      EXPECT_GT(s.flagged_pairs, 0u) << "a contact needs a flagged region pair";
    }
    EXPECT_EQ(s.fallback_pairs, 0u);
    // Times of this step only (not summed over steps, not in other units): inside the step's wall time.
    EXPECT_GT(s.ms_sensor_step, 0.0);
    if (s.exact_tests > 0) {
      EXPECT_GT(s.ms_exact, 0.0);
    }
    EXPECT_LT(s.ms_sensor_step + s.ms_exact, wall_ms);
    if (s.contacts > 0) ++steps_with_contacts;
  }
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

// Each body's contact array gets room for all its candidates before the exact stage makes a
// contact (so it never grows while it fills), and holds about the most a step has needed, not
// Bullet's doubling: at most an eighth more than the largest count of candidates it has had, and
// twice the largest growth of that count from one step to the next. While the count grows, that
// room spares it a new block in some of the steps.
TEST(Stats, ContactArraysHoldRoomForTheirCandidatesAndLittleMore) {
  psc_test::SoftWorld w(0);
  psc_test::buildScene(Scene::ThreeInARow, w);
  auto plugin = psc::bullet::install(w.world);
  const auto& bodies = w.world.getSoftBodyArray();
  const auto n = static_cast<std::size_t>(bodies.size());
  std::vector<std::size_t> most(n, 0), last(n, 0), growth(n, 0), capacity(n, 0);
  std::size_t steps_with_contacts = 0, growing = 0, taken_anew = 0;
  for (int step = 0; step < 60; ++step) {
    bool any = false;
    w.run(1, [&] {
      const auto& candidates = plugin.sensorWorld().lastResult().candidates;
      for (int b = 0; b < bodies.size(); ++b) {
        const std::optional<psc::BodyId> id = plugin.bodyId(bodies[b]);
        ASSERT_TRUE(id.has_value());
        std::size_t need = 0;
        for (const psc::CandidatePair& c : candidates) need += c.vertex_body == *id;
        const auto k = static_cast<std::size_t>(b);
        std::size_t& m = most[k];
        m = std::max(m, need);
        if (need > last[k]) {
          growth[k] = std::max(growth[k], need - last[k]);
          ++growing;
        }
        last[k] = need;
        const auto& list = bodies[b]->m_scontacts;
        const auto cap = static_cast<std::size_t>(list.capacity());
        EXPECT_GE(cap, need) << "body " << b << ", step " << step;
        EXPECT_LE(cap, m + m / 8 + 2 * growth[k]) << "body " << b << ", step " << step;
        taken_anew += cap != capacity[k];
        capacity[k] = cap;
        any = any || list.size() > 0;
      }
    });
    steps_with_contacts += any;
  }
  EXPECT_GT(steps_with_contacts, 20u) << "the scene must make contacts in many steps for the test to mean anything";
  std::printf("[ contact arrays ] %zu body-steps whose candidates grew, %zu new blocks\n", growing, taken_anew);
  EXPECT_LT(taken_anew, growing) << "a growing array got a new block at every growth";
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

// A sphere moving 1 unit per step into another: Bullet's radius margins + 2·|Δx| reaches nearly
// every face of the other sphere from each moving node, far beyond resting contact; the step
// reports the pair as a runaway, naming both bodies. Three spheres in a row at rest in contact do not.
TEST(Stats, RunawayPairsAreReportedWithTheBodiesAndTheContactCount) {
  psc_test::SoftWorld w(0);
  w.addSoft(psc::makeSphere(1.0, 300));
  w.addSoft(psc::makeSphere(1.0, 300).translate({2.5, 0, 0}), {}, {-60, 0, 0});
  auto plugin = psc::bullet::install(w.world);
  w.run(1);
  const psc::bullet::Stats& s = plugin.stats();
  const auto& bodies = w.world.getSoftBodyArray();
  EXPECT_GT(double(s.contacts), psc::bullet::runawayContacts(*bodies[0], *bodies[1]));
  EXPECT_EQ(s.runaway_pairs, 1u);
  EXPECT_NE(s.runaway.find("soft bodies 0 and 1"), std::string::npos) << s.runaway;
  EXPECT_NE(s.runaway.find(std::to_string(s.contacts) + " contacts"), std::string::npos) << s.runaway;

  psc_test::SoftWorld rest(0);
  psc_test::buildScene(Scene::ThreeInARow, rest);
  auto quiet = psc::bullet::install(rest.world);
  for (int step = 0; step < 20; ++step) {
    rest.run(1);
    EXPECT_EQ(quiet.stats().runaway_pairs, 0u) << "step " << step << ": " << quiet.stats().runaway;
  }
}
