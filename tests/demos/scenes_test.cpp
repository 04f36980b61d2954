// Every scene builds and runs a few steps with both pipelines; scene definitions are deterministic
// and honour their parameters; a longer head-on run checks the measurement chain end to end.
#include "ground_truth.h"
#include "psc/error.h"
#include "runner.h"
#include "scenes.h"
#include "sensor_pipeline.h"

#include <gtest/gtest.h>

#include <cstdio>

namespace psc::demo {
namespace {

class EveryScene : public ::testing::TestWithParam<std::string> {};

TEST_P(EveryScene, BuildsAndRunsAFewStepsWithBothPipelines) {
  SceneParams p;
  p.resolution = 80;
  p.bodies = 3;
  const Scene scene = makeScene(GetParam(), p);
  ASSERT_GE(scene.bodies.size(), 2u);
  for (const SoftBodySpec& b : scene.bodies) {
    EXPECT_FALSE(b.mesh.triangles.empty()) << b.name;
    for (const Vec3& v : b.mesh.vertices) ASSERT_TRUE(v.allFinite()) << b.name;
  }
  std::vector<Pipeline> pipelines{Pipeline::Bullet};
  if (SensorPipeline::available()) pipelines.insert(pipelines.begin(), Pipeline::Sensors);
  for (Pipeline pipeline : pipelines) {
    RunOptions o;
    o.steps = 4;
    const RunResult r = runPipeline(scene, pipeline, o);
    EXPECT_EQ(r.steps, 4u);
    EXPECT_EQ(r.bodies, scene.bodies.size());
    EXPECT_GE(r.recall_strict, 0.0);
    EXPECT_LE(r.recall_strict, 1.0);
    EXPECT_GE(r.recall_full, 0.0);
    EXPECT_LE(r.recall_full, 1.0);
    EXPECT_EQ(r.contacts_outside_truth, 0u) << "both pipelines end in Bullet's own exact test";
    EXPECT_GT(r.step_ms_median, 0.0);
    EXPECT_GT(r.peak_rss_mb, 0.0);
    EXPECT_TRUE(r.pipeline_error.empty()) << r.pipeline_error;
  }
  if (!SensorPipeline::available()) GTEST_SKIP() << "psc::bullet not built: the sensors pipeline was not run";
}

std::vector<std::string> sceneNames() {
  std::vector<std::string> names;
  for (const SceneInfo& s : sceneCatalog()) names.push_back(s.name);
  return names;
}

TEST_P(EveryScene, StartsWithBodiesApart) {
  // A scene that starts interpenetrating measures its own setup, not a pipeline.
  for (std::size_t res : {300, 2000}) {
    SceneParams p;
    p.resolution = res;
    const Scene scene = makeScene(GetParam(), p);
    std::vector<TruthBody> bodies;
    for (const SoftBodySpec& b : scene.bodies) {
      TruthBody t;
      t.x = t.prev = b.mesh.vertices;
      t.triangles = b.mesh.triangles;
      t.margin = b.margin;
      t.closed = b.closed;
      bodies.push_back(std::move(t));
    }
    TriangleGrid grid;
    EXPECT_EQ(measurePenetration(bodies, grid).vertices, 0u) << res;
    GroundTruth truth;
    EXPECT_EQ(truth.compute(bodies, {}).strict_inside, 0u) << res;
  }
}

INSTANTIATE_TEST_SUITE_P(Catalog, EveryScene, ::testing::ValuesIn(sceneNames()),
                         [](const ::testing::TestParamInfo<std::string>& param_info) { return param_info.param; });

TEST(Scenes, CatalogFollowsTheBenchmarkNumbering) {
  EXPECT_EQ(sceneCatalog().size(), 9u);
  for (const char* key : {"1", "2", "2a", "2b", "3", "4", "5", "6", "7", "8", "head_on", "mesh"})
    EXPECT_NE(findScene(key), nullptr) << key;
  try {
    makeScene("nonsense", {});
    FAIL() << "an unknown scene must throw";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("unknown scene 'nonsense'"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("tori_pile"), std::string::npos) << "the message lists the scenes";
  }
}

TEST(Scenes, DeterministicAndHonourTheirParameters) {
  SceneParams p;
  p.resolution = 300;
  p.bodies = 5;
  p.seed = 3;
  const Scene a = makeScene("tori_pile", p), b = makeScene("tori_pile", p);
  ASSERT_EQ(a.bodies.size(), 5u);
  for (std::size_t i = 0; i < a.bodies.size(); ++i) EXPECT_EQ(a.bodies[i].mesh.vertices, b.bodies[i].mesh.vertices);
  p.seed = 4;
  const Scene c = makeScene("tori_pile", p);
  EXPECT_NE(a.bodies[1].mesh.vertices, c.bodies[1].mesh.vertices) << "another seed, another pile";
  for (std::size_t res : {200, 1000, 3000}) {
    p.resolution = res;
    const Scene s = makeScene("head_on", p);
    EXPECT_NEAR(double(s.resolution()), double(res), 0.15 * double(res)) << res;
    EXPECT_EQ(s.bodies.size(), 2u) << "head_on ignores --bodies";
  }
}

TEST(Scenes, HeadOnMeasurementChain) {
  // Long enough for the spheres to meet: both pipelines find contacts, every contact is in the
  // truth, and the figures are printed for the record.
  SceneParams p;
  p.resolution = 300;
  const Scene scene = makeScene("head_on", p);
  std::vector<Pipeline> pipelines{Pipeline::Bullet};
  if (SensorPipeline::available()) pipelines.push_back(Pipeline::Sensors);
  for (Pipeline pipeline : pipelines) {
    RunOptions o;
    o.steps = 40;
    const RunResult r = runPipeline(scene, pipeline, o);
    std::printf("head_on 300v %s: strict %.4f (worst %.3f), full %.4f, pairs %.3f, contacts %zu, coll %.3f ms\n",
                toString(pipeline), r.recall_strict, r.recall_strict_worst_step, r.recall_full, r.pair_recall,
                r.contacts_found_total, r.collision_ms_median);
    EXPECT_GT(r.truth_strict_total, 0u);
    EXPECT_GT(r.contacts_found_total, 0u);
    EXPECT_EQ(r.contacts_outside_truth, 0u);
    EXPECT_GT(r.exact_tests_per_step, 0.0);
    EXPECT_GT(r.midphase_bytes_per_vertex, 0.0);
    if (pipeline == Pipeline::Sensors) {
      EXPECT_GT(r.particles, 0u);
      EXPECT_GT(r.flagged_pairs_per_step, 0.0);
    }
  }
}

}  // namespace
}  // namespace psc::demo
