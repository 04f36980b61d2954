// The benchmark's ground truth against references: the grid against brute force (random soups and
// real scene states, both radii), and the inside test against shapes whose inside is known. The
// exact distance itself is psc::testkit's, tested in tests/testkit_test.cpp.
#include "bullet_scene.h"
#include "ground_truth.h"
#include "psc/testkit/reference.h"
#include "scenes.h"

#include <gtest/gtest.h>

#include <cmath>
#include <random>

namespace psc::demo {
namespace {

Vec3 randomVec(std::mt19937_64& rng, double lo, double hi) {
  std::uniform_real_distribution<double> u(lo, hi);
  return {u(rng), u(rng), u(rng)};
}

/// Bodies of random small triangles in overlapping boxes, with random margins and motion.
std::vector<TruthBody> randomSoup(std::uint64_t seed, int bodies, int triangles) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(0, 1);
  std::vector<TruthBody> out(static_cast<std::size_t>(bodies));
  for (int b = 0; b < bodies; ++b) {
    TruthBody& body = out[static_cast<std::size_t>(b)];
    const Vec3 center = randomVec(rng, -0.3, 0.3);
    body.margin = 0.01 + 0.03 * u(rng);
    for (int t = 0; t < triangles; ++t) {
      const Vec3 base = center + randomVec(rng, -0.5, 0.5);
      for (int k = 0; k < 3; ++k) {
        body.x.push_back(base + randomVec(rng, -0.08, 0.08));
        // A few vertices move far in one step, so the full radius differs much from the strict one.
        const double reach = u(rng) < 0.1 ? 0.1 : 0.01;
        body.prev.push_back(body.x.back() + randomVec(rng, -reach, reach));
      }
      const auto i = static_cast<Index>(3 * t);
      body.triangles.push_back({i, i + 1, i + 2});
    }
  }
  return out;
}

std::vector<std::vector<Triangle>> trianglesOf(const std::vector<TruthBody>& bodies) {
  std::vector<std::vector<Triangle>> out;
  for (const TruthBody& b : bodies) out.push_back(b.triangles);
  return out;
}

void expectSame(const TruthResult& grid, const TruthResult& brute, const std::string& what) {
  ASSERT_EQ(grid.contacts.size(), brute.contacts.size()) << what;
  for (std::size_t i = 0; i < grid.contacts.size(); ++i) {
    const TruthContact &g = grid.contacts[i], &b = brute.contacts[i];
    ASSERT_TRUE(g.key == b.key) << what << " contact " << i;
    ASSERT_EQ(g.strict, b.strict) << what << " contact " << i;
    ASSERT_EQ(g.full, b.full) << what << " contact " << i;
    ASSERT_EQ(g.distance, b.distance) << what << " contact " << i;
  }
  EXPECT_EQ(grid.strict_inside, brute.strict_inside) << what;
  EXPECT_EQ(grid.full_inside, brute.full_inside) << what;
  EXPECT_LT(grid.distance_tests, brute.distance_tests) << what << ": the grid should prune";
}

TEST(TruthGrid, EqualsBruteForceOnRandomSoups) {
  GroundTruth truth;
  std::size_t strict_seen = 0, full_only_seen = 0, ambiguous_seen = 0;
  for (std::uint64_t seed = 1; seed <= 12; ++seed) {
    const auto bodies = randomSoup(seed, 2 + int(seed % 4), 60);
    for (int mode = 0; mode < 3; ++mode) {
      TruthSettings s;
      s.strict = mode != 2;
      s.full = mode != 1;
      s.band_absolute = seed % 2 ? 0.0 : 2e-3;  // also exercise the ambiguous band
      const TruthResult brute = groundTruthBruteForce(bodies, s);
      expectSame(truth.compute(bodies, s), brute, "seed " + std::to_string(seed) + " mode " + std::to_string(mode));
      if (mode == 0) {
        strict_seen += brute.strict_inside;
        full_only_seen += brute.full_inside - std::min(brute.full_inside, brute.strict_inside);
        ambiguous_seen += brute.strict_ambiguous + brute.full_ambiguous;
      }
    }
  }
  // The comparison must have had something to compare in every class.
  EXPECT_GT(strict_seen, 100u);
  EXPECT_GT(full_only_seen, 100u);
  EXPECT_GT(ambiguous_seen, 0u);
}

std::vector<TruthBody> bodiesOf(SceneWorld& sw) {
  std::vector<TruthBody> out;
  for (std::size_t i = 0; i < sw.softBodies().size(); ++i) {
    const btSoftBody* psb = sw.softBodies()[i];
    TruthBody b;
    for (int v = 0; v < psb->m_nodes.size(); ++v) {
      const auto& n = psb->m_nodes[v];
      b.x.emplace_back(n.m_x.x(), n.m_x.y(), n.m_x.z());
      b.prev.emplace_back(n.m_q.x(), n.m_q.y(), n.m_q.z());
    }
    b.triangles = sw.scene().bodies[i].mesh.triangles;
    b.margin = psb->getCollisionShape()->getMargin();
    b.closed = sw.scene().bodies[i].closed;
    out.push_back(std::move(b));
  }
  return out;
}

TEST(TruthGrid, EqualsBruteForceOnSceneStates) {
  struct Case {
    const char* scene;
    std::size_t resolution, steps;
  };
  const Case cases[] = {{"head_on", 150, 20}, {"row_mixed", 120, 25}, {"interlock", 150, 20},
                        {"tori_pile", 120, 60}, {"cloth_ball", 150, 40}, {"fast_impact", 120, 8}};
  GroundTruth truth;
  std::size_t strict_total = 0;
  for (const Case& c : cases) {
    SceneParams p;
    p.resolution = c.resolution;
    p.bodies = 3;
    const Scene scene = makeScene(c.scene, p);
    SceneWorld sw(scene);
    // The state contacts are decided on: right after collision detection (m_x predicted).
    std::vector<TruthBody> bodies;
    sw.world().after_collision = [&] { bodies = bodiesOf(sw); };
    for (std::size_t s = 0; s < c.steps; ++s) sw.step();
    TruthSettings s;
    s.band_absolute = 1e-6;
    const TruthResult brute = groundTruthBruteForce(bodies, s);
    expectSame(truth.compute(bodies, s), brute, c.scene);
    strict_total += brute.strict_inside;
  }
  EXPECT_GT(strict_total, 20u) << "the scene states should be in contact";
}

/// Rest shapes for `bodies`: the positions moved by up to `shift` per vertex, so that some pairs
/// within the radius now were close at rest (excluded) and some were not.
std::vector<std::vector<Vec3>> restOf(const std::vector<TruthBody>& bodies, std::uint64_t seed, double shift) {
  std::mt19937_64 rng(seed);
  std::vector<std::vector<Vec3>> rest;
  for (const TruthBody& b : bodies) {
    rest.push_back(b.x);
    for (Vec3& p : rest.back()) p += randomVec(rng, -shift, shift);
  }
  return rest;
}

TEST(SelfTruth, GridEqualsBruteForceOnRandomSoups) {
  GroundTruth truth;
  std::size_t strict_seen = 0, excluded_seen = 0;
  for (std::uint64_t seed = 1; seed <= 8; ++seed) {
    // Fewer bodies, more triangles each: a body's own triangles overlap.
    const auto bodies = randomSoup(seed, 1 + int(seed % 2), 120);
    SelfRule rule = selfRule(trianglesOf(bodies), restOf(bodies, seed, 0.1));
    rule.radius_edges = seed % 4 < 2 ? 0.0 : 1.0;  // 2 × margin, or the mean edge (larger)
    for (int mode = 0; mode < 3; ++mode) {
      TruthSettings s;
      s.strict = mode != 2;
      s.full = mode != 1;
      s.band_absolute = seed % 2 ? 0.0 : 2e-3;
      const TruthResult brute = groundTruthSelfBruteForce(bodies, rule, s);
      const std::string what = "seed " + std::to_string(seed) + " mode " + std::to_string(mode);
      expectSame(truth.computeSelf(bodies, rule, s), brute, what);
      for (const TruthContact& c : brute.contacts) ASSERT_EQ(c.key.vertex_body, c.key.triangle_body) << what;
      if (mode == 0) {
        strict_seen += brute.strict_inside;
        // The same without exclusion at rest (a rest shape far apart): what the rule took out.
        SelfRule apart = rule;
        for (auto& body : apart.rest)
          for (std::size_t v = 0; v < body.size(); ++v) body[v] *= 1e3 * double(v + 1);
        excluded_seen += groundTruthSelfBruteForce(bodies, apart, s).strict_inside - brute.strict_inside;
      }
    }
  }
  EXPECT_GT(strict_seen, 100u);
  EXPECT_GT(excluded_seen, 10u);
}

TEST(SelfTruth, FoldedClothAgainstBruteForceAndTheInitialShapeAsRest) {
  // cloth_fold (Bullet's pipeline: no self-collision) with the scene's initial mesh as rest shape,
  // at the step its halves touch most.
  const Scene scene = makeScene("cloth_fold", SceneParams{});
  const SelfRule rule = selfRule({scene.bodies[0].mesh.triangles}, {scene.bodies[0].mesh.vertices});
  TruthSettings s;
  s.band_absolute = 1e-6;
  GroundTruth truth;
  SceneWorld sw(scene);
  std::vector<TruthBody> bodies, most;
  std::size_t first_step_contacts = 0, most_strict = 0;
  int step = 0;
  sw.world().after_collision = [&] {
    bodies = bodiesOf(sw);
    const TruthResult& r = truth.computeSelf(bodies, rule, s);
    if (step == 0) first_step_contacts = r.contacts.size();
    if (r.strict_inside > most_strict) most_strict = r.strict_inside, most = bodies;
  };
  for (; step < 180; ++step) sw.step();
  // The flat cloth at its first step touches itself nowhere the rule leaves in.
  EXPECT_EQ(first_step_contacts, 0u);
  ASSERT_GT(most_strict, 20u) << "the folded cloth should touch itself";
  const TruthResult brute = groundTruthSelfBruteForce(most, rule, s);
  expectSame(truth.computeSelf(most, rule, s), brute, "cloth_fold");
}

TEST(SelfTruth, TheInitialMeshExcludesWhatThePluginsFirstStepExcludes) {
  // The plugin takes its rest shape at its first step (m_x after the first predictMotion); the self
  // truth takes the scene's initial mesh. Every pair of the self scenes is excluded by both or by
  // neither.
  for (const char* name : {"cloth_fold", "tube_coil"}) {
    const Scene scene = makeScene(name, SceneParams{});
    SceneWorld sw(scene);
    std::vector<TruthBody> bodies;
    sw.world().after_collision = [&] { bodies = bodiesOf(sw); };
    sw.step();
    const std::vector<Vec3>& initial = scene.bodies[0].mesh.vertices;
    const TruthBody& first = bodies.at(0);
    const SelfRule by_initial_rule = selfRule({first.triangles}, {initial});
    const SelfRule by_first_rule = selfRule({first.triangles}, {first.x});
    const double radius = by_initial_rule.radius(first, 0);
    EXPECT_NEAR(by_first_rule.radius(first, 0), radius, 1e-6 * radius) << name;
    std::size_t excluded = 0;
    for (Index v = 0; v < initial.size(); ++v)
      for (const Triangle& t : first.triangles) {
        const bool by_initial = testkit::selfPairExcluded(v, t, initial, radius, 2.0);
        ASSERT_EQ(by_initial, testkit::selfPairExcluded(v, t, first.x, radius, 2.0)) << name << " vertex " << v;
        excluded += by_initial;
      }
    EXPECT_GT(excluded, 3 * initial.size()) << name << ": the rule excludes every vertex's own neighbourhood";
  }
}

TEST(TruthInside, BoxWithRaysAlongEdgesAndVertices) {
  // A tessellated box has vertices and edges exactly on the rays from grid-aligned points: the tie
  // rule must still count each crossing of the surface once.
  TruthBody box;
  const TriMesh m = makeBox(Vec3(1, 1, 1), 300);
  box.x = m.vertices;
  box.prev = m.vertices;
  box.triangles = m.triangles;
  box.closed = true;
  std::vector<TruthBody> bodies{box};
  TriangleGrid grid;
  grid.build(bodies);
  std::size_t inside = 0, outside = 0;
  for (double x : {-1.5, -0.5, 0.0, 0.25, 0.5, 1.5})
    for (double y : {-1.5, -0.5, 0.0, 0.5, 1.5})
      for (double z : {-0.5, 0.0, 0.5, 1.5}) {
        const Vec3 p(x, y, z);
        const bool truly_inside = std::abs(x) < 1 && std::abs(y) < 1 && std::abs(z) < 1;
        for (int axis = 0; axis < 3; ++axis)
          EXPECT_EQ(grid.rayParityOdd(p, 0, axis), truly_inside) << x << ' ' << y << ' ' << z << " axis " << axis;
        (truly_inside ? inside : outside) += 1;
      }
  EXPECT_GT(inside, 20u);
  EXPECT_GT(outside, 20u);
}

TEST(TruthInside, PenetrationDepthAndMargins) {
  TruthBody ball;
  const TriMesh m = makeIcosphere(1.0, 3);
  ball.x = ball.prev = m.vertices;
  ball.triangles = m.triangles;
  ball.closed = true;
  ball.margin = 0.05;
  // Body A: three loose triangles: one vertex at the centre (depth ~1), one just under the
  // surface (inside, but within the margins: not a penetration), the rest far outside.
  TruthBody a;
  a.margin = 0.05;
  a.x = {Vec3(0, 0, 0), Vec3(3, 0, 0), Vec3(3, 1, 0), Vec3(0.95, 0, 0.05), Vec3(3, 0, 1), Vec3(3, 1, 1)};
  a.prev = a.x;
  a.triangles = {{0, 1, 2}, {3, 4, 5}};
  std::vector<TruthBody> bodies{ball, a};
  TriangleGrid grid;
  const Penetration pen = measurePenetration(bodies, grid);
  EXPECT_EQ(pen.vertices, 1u);
  EXPECT_GT(pen.max_depth, 0.97);  // the icosphere's faces sit a little inside the unit sphere
  EXPECT_LE(pen.max_depth, 1.0);
  // Open bodies have no inside: the same points against a cloth patch give nothing.
  bodies[0].closed = false;
  EXPECT_EQ(measurePenetration(bodies, grid).vertices, 0u);
}

}  // namespace
}  // namespace psc::demo
