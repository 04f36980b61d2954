// Recall of the plugin and of Bullet's default VF_SS pipeline against the exact brute-force ground
// truth (docs/BENCHMARK.md), on small versions of the recall scenes. Both are measured in the same
// process on the same scene; each against the truth of its own trajectory, at the moment of the
// dispatch (positions predicted, soft solve not yet run).
#include "ground_truth.h"
#include "psc/bullet/bullet.h"
#include "soft_world.h"

#include <gtest/gtest.h>

#include <cstdio>
#include <optional>

namespace {

using psc_test::Scene;

struct Run {
  psc_test::RecallMeter meter;
  std::size_t steps = 0;
  std::size_t exact_tests = 0;
  std::size_t flagged_pairs = 0;
  std::size_t candidate_pairs = 0;
  std::size_t particles = 0;
  std::size_t round_cap_hits = 0;
  double ms_sensor = 0.0;
  double ms_exact = 0.0;
  double ms_movement = 0.0, ms_flagging = 0.0, ms_candidates = 0.0, ms_repartition = 0.0;
  std::size_t repartitions = 0;
};

Run runScene(Scene scene, bool with_plugin) {
  psc_test::SoftWorld w(psc_test::sceneGravity(scene));
  psc_test::buildScene(scene, w);
  std::optional<psc::bullet::Plugin> plugin;
  if (with_plugin) plugin = psc::bullet::install(w.world);
  Run run;
  w.run(psc_test::sceneSteps(scene), [&] {
    const auto& bodies = w.world.getSoftBodyArray();
    run.meter.add(psc_test::bruteForceContacts(bodies), psc_test::foundContacts(bodies));
    ++run.steps;
    if (plugin) {
      const psc::bullet::Stats& s = plugin->stats();
      EXPECT_TRUE(s.error.empty()) << s.error;
      EXPECT_EQ(s.skipped_bodies, 0u) << s.skipped_reason;
      run.exact_tests += s.exact_tests;
      run.flagged_pairs += s.flagged_pairs;
      run.candidate_pairs += s.candidate_pairs;
      run.particles = s.particles;
      run.round_cap_hits += s.round_cap_hits;
      run.ms_sensor += s.ms_sensor_step;
      run.ms_exact += s.ms_exact;
      run.ms_movement += s.core.ms_sensors;
      run.ms_flagging += s.core.ms_flagging;
      run.ms_candidates += s.core.ms_candidates;
      run.ms_repartition += s.core.ms_repartition;
      run.repartitions += s.repartitions;
    }
  });
  return run;
}

void report(Scene scene, const Run& psc, const Run& bullet) {
  std::printf("%s\n", psc.meter.line(psc_test::sceneName(scene), "psc").c_str());
  std::printf("%s\n", bullet.meter.line(psc_test::sceneName(scene), "bullet").c_str());
  const double steps = double(psc.steps);
  std::printf("  psc per step: particles=%zu flagged=%.1f candidates=%.1f exact-tests=%.1f; round-cap-hits=%zu "
              "repartitions=%zu; sensor step %.3f ms (movement %.3f, flagging %.3f, candidates %.3f, repartition "
              "%.3f), exact %.3f ms; faces Bullet cannot test: %zu\n",
              psc.particles, double(psc.flagged_pairs) / steps, double(psc.candidate_pairs) / steps,
              double(psc.exact_tests) / steps, psc.round_cap_hits, psc.repartitions, psc.ms_sensor / steps,
              psc.ms_movement / steps, psc.ms_flagging / steps, psc.ms_candidates / steps, psc.ms_repartition / steps,
              psc.ms_exact / steps, psc.meter.degenerateFaces());
}

/// Floors per scene, from the measured figures (bullet_plugin/README.md, closing note of issue 3):
/// the plugin found every strict-radius and every full-radius contact on all four scenes. Strict
/// stays at 1: no contact inside the margins may ever be missed. Full leaves 1e-3 for contacts of
/// nodes whose motion term puts them within float rounding of the radius, where Bullet decides in
/// btScalar and the truth in double.
struct Floors {
  double strict = 1.0;
  double full = 0.999;
  /// Steps whose particle movement stopped at SensorSettings::max_rounds: 0 measured on every scene
  /// but the pile (5 of 150 steps, while the bodies settle); the pile's bound is 5% of its steps.
  std::size_t round_cap_hits = 0;
};

void checkScene(Scene scene, Floors floors) {
  const Run psc = runScene(scene, true);
  const Run bullet = runScene(scene, false);
  report(scene, psc, bullet);
  // The scene must exercise something, in both runs.
  EXPECT_GT(psc.meter.truthStrict(), 50u);
  EXPECT_GT(bullet.meter.truthStrict(), 50u);
  // An exact narrow phase reports nothing outside Bullet's own acceptance radius.
  EXPECT_EQ(psc.meter.falseContacts(), 0u);
  EXPECT_EQ(bullet.meter.falseContacts(), 0u);
  EXPECT_GE(psc.meter.strictRecall(), floors.strict) << psc.meter.missedStrict() << " strict contacts missed";
  EXPECT_GE(psc.meter.fullRecall(), floors.full) << psc.meter.missedFull() << " full-radius contacts missed";
  EXPECT_GE(psc.meter.pairRecall(), 1.0);
  EXPECT_LE(psc.round_cap_hits, floors.round_cap_hits);
}

TEST(Recall, TwoSpheresHeadOn) { checkScene(Scene::HeadOn, {}); }
TEST(Recall, ThreeSpheresInARow) { checkScene(Scene::ThreeInARow, {}); }
TEST(Recall, TwoLinkedTori) { checkScene(Scene::Concave, {}); }
TEST(Recall, MixedPileOfSevenBodies) {
  Floors floors;
  floors.round_cap_hits = 7;
  checkScene(Scene::Pile, floors);
}

}  // namespace
