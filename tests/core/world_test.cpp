// The SensorWorld against brute force: the thesis's chapter-4 cases placed by hand, candidate
// sets, determinism, repartitioning and bad input.

#include "test_util.h"

// Private: the switch between the candidate stage's two probe paths (Probes.* below).
#include "../../src/bounds.h"

#include "psc/error.h"
#include "psc/repartition.h"
#include "psc/shapes.h"
#include "psc/testkit/reference.h"
#include "psc/world.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <tuple>
#include <cmath>
#include <cstring>
#include <functional>
#include <iostream>
#include <limits>
#include <map>
#include <memory>
#include <random>
#include <set>

namespace psc {
namespace {

constexpr double kPi = 3.14159265358979323846;

struct Scene {
  std::vector<TriMesh> meshes;
  std::vector<BodyId> ids;
  SensorWorld world;
  explicit Scene(const SensorSettings& s = {}) : world(s) {}
  // Views point into `meshes`, so add all meshes first, then register.
  void registerAll(double margin) {
    for (std::size_t i = 0; i < meshes.size(); ++i) {
      BodyDesc d;
      d.triangles = meshes[i].triangles;
      d.positions = PositionView::of(meshes[i].vertices);
      d.margin = margin;
      d.name = "mesh" + std::to_string(i);
      ids.push_back(world.addBody(d));
    }
  }
};

double meanEdge(const TriMesh& m) {
  MeshTopology t(m.triangles, m.vertices.size());
  return edgeStats(t, PositionView::of(m.vertices)).mean;
}

struct CoverageReport {
  std::size_t truth = 0;          // true contacts (vertex-triangle distance < radius)
  std::size_t in_sets = 0;        // ... lying in some flagged pair's candidate sets
  std::size_t in_pairs = 0;       // ... appearing among the step's candidate pairs
  std::size_t sensor_sets = 0;    // ... lying in the sets of a pair flagged by the sensors alone
};

// For every ordered pair of bodies: brute-force contacts within `radius`, and where they are found.
CoverageReport coverage(Scene& sc, const StepResult& res, double radius) {
  CoverageReport rep;
  std::set<std::tuple<BodyId, Index, BodyId, Index>> cand;
  for (const CandidatePair& c : res.candidates) cand.insert({c.vertex_body, c.vertex, c.triangle_body, c.triangle});
  // Expand each flagged pair's sets once.
  struct Sets {
    BodyId vb, tb;
    std::set<Index> v, t;
    bool sensors;
  };
  std::vector<Sets> sets;
  for (const FlaggedPair& f : res.flagged)
    for (BodyId vb : {f.body_a, f.body_b}) {
      const testkit::RegionSets cs = testkit::regionSets(sc.world, f, vb);
      sets.push_back({vb, vb == f.body_a ? f.body_b : f.body_a, {cs.vertices.begin(), cs.vertices.end()},
                      {cs.triangles.begin(), cs.triangles.end()}, f.by_sensors});
    }
  for (std::size_t i = 0; i < sc.meshes.size(); ++i)
    for (std::size_t j = 0; j < sc.meshes.size(); ++j) {
      if (i == j) continue;
      for (const auto& [v, t] : testkit::bruteContacts(sc.meshes[i], sc.meshes[j], radius)) {
        ++rep.truth;
        bool in = false, by_sensor = false;
        for (const Sets& s : sets)
          if (s.vb == sc.ids[i] && s.tb == sc.ids[j] && s.v.count(v) && s.t.count(t)) {
            in = true;
            by_sensor = by_sensor || s.sensors;
          }
        rep.in_sets += in;
        rep.sensor_sets += by_sensor;
        rep.in_pairs += cand.count({sc.ids[i], v, sc.ids[j], t});
      }
    }
  return rep;
}

// Runs a few steps (the particles need rounds to settle) and checks coverage of the last step:
// the default midphase hands over every contact within the margins; the same scene in the thesis's
// flag-only mode must be flagged by the sensors themselves.
void expectFullCoverage(Scene& sc, double margin, const char* what) {
  sc.registerAll(margin);
  const StepResult* res = nullptr;
  for (int s = 0; s < 3; ++s) {
    res = &sc.world.step();
    // The particles settle well inside the round cap (64) on every chapter-4 scene.
    EXPECT_EQ(res->stats.round_cap_hits, 0u) << what << ", step " << s;
    EXPECT_LE(res->stats.rounds, 32) << what << ", step " << s;
  }
  const CoverageReport atMargin = coverage(sc, *res, 2.0 * margin);

  SensorSettings thesis_settings;
  thesis_settings.flagging = Flagging::Sensors;
  Scene thesis(thesis_settings);
  thesis.meshes = sc.meshes;
  thesis.registerAll(margin);
  const StepResult* th = nullptr;
  for (int s = 0; s < 3; ++s) th = &thesis.world.step();
  const double mu = thesis.world.mu(thesis.ids[0], thesis.ids[1]);
  const CoverageReport atMu = coverage(thesis, *th, mu);
  std::cout << "[ chapter 4 ] " << what << ": " << atMargin.truth << " contacts within the margins, "
            << atMargin.in_pairs << " among the default's candidate pairs (" << res->stats.region_pairs
            << " region pairs boxed, " << res->stats.region_pairs_separated << " separated by the sensors); thesis mode: "
            << atMu.in_sets << " of " << atMu.truth << " contacts within mu=" << mu << " in sensor-flagged sets, "
            << th->stats.flagged_by_sensors << " pairs flagged by sensors, " << th->stats.particles << " particles, "
            << th->stats.rounds << " rounds\n";
  EXPECT_GT(atMargin.truth, 0u) << what << ": the scene must touch";
  EXPECT_EQ(atMargin.in_pairs, atMargin.truth) << what;
  EXPECT_GT(th->stats.flagged_by_sensors, 0u) << what << ": the sensors themselves must flag the contact";
  EXPECT_GT(atMu.in_sets, 0u) << what;
}

TEST(Chapter4, TwoEqualSpheresTouching) {
  Scene sc;
  TriMesh a = makeSphere(1.0, 600), b = makeSphere(1.0, 600);
  const double gap = 0.3 * meanEdge(a);
  b.rotate(Vec3(0.3, 1, 0.2), 0.7).translate(Vec3(2.0 + gap, 0, 0));
  sc.meshes = {a, b};
  expectFullCoverage(sc, 0.4 * meanEdge(a), "two equal spheres");
}

TEST(Chapter4, ThreeEqualSpheresInARow) {
  Scene sc;
  TriMesh a = makeSphere(1.0, 600), b = makeSphere(1.0, 600), c = makeSphere(1.0, 600);
  const double gap = 0.3 * meanEdge(a);
  b.translate(Vec3(2.0 + gap, 0, 0));
  c.translate(Vec3(4.0 + 2 * gap, 0, 0));
  sc.meshes = {a, b, c};
  expectFullCoverage(sc, 0.4 * meanEdge(a), "three equal spheres");
}

TEST(Chapter4, SpheresDHalfDD) {
  Scene sc;
  TriMesh a = makeSphere(1.0, 600), b = makeSphere(0.5, 300), c = makeSphere(1.0, 600);
  const double gap = 0.3 * meanEdge(b);
  b.translate(Vec3(1.5 + gap, 0, 0));
  c.translate(Vec3(3.0 + 2 * gap, 0, 0));
  sc.meshes = {a, b, c};
  expectFullCoverage(sc, 0.4 * meanEdge(b), "spheres D, D/2, D");
}

TEST(Chapter4, InterlockingUShapes) {
  Scene sc;
  const double e = meanEdge(makeUShape(1.0, 1.0, 0.2, 1200));
  const std::array<TriMesh, 2> us = test::interlockedUShapes(0.3 * e);
  sc.meshes = {us[0], us[1]};
  expectFullCoverage(sc, 0.6 * e, "interlocking U shapes");
}

void checkCandidates(Flagging mode) {
  SensorSettings s;
  s.flagging = mode;
  Scene sc(s);
  TriMesh a = makeSphere(1.0, 1500), b = makeTorus(0.8, 0.3, 1500);
  b.rotate(Vec3(1, 0, 0), kPi / 2).translate(Vec3(1.95, 0.1, 0));
  sc.meshes = {a, b};
  const double margin = 0.5 * meanEdge(a);
  sc.registerAll(margin);
  const StepResult& res = sc.world.step();
  ASSERT_GT(res.flagged.size(), 0u);
  std::set<std::tuple<BodyId, Index, BodyId, Index>> cand;
  for (const CandidatePair& c : res.candidates) cand.insert({c.vertex_body, c.vertex, c.triangle_body, c.triangle});
  EXPECT_EQ(cand.size(), res.candidates.size()) << "each (vertex, triangle) at most once";
  std::size_t near = 0, all_pairs = 0;
  for (const FlaggedPair& f : res.flagged)
    for (BodyId vb : {f.body_a, f.body_b}) {
      const testkit::RegionSets cs = testkit::regionSets(sc.world, f, vb);
      const BodyId tb = vb == f.body_a ? f.body_b : f.body_a;
      const TriMesh& vm = sc.meshes[vb == sc.ids[0] ? 0 : 1];
      const TriMesh& tm = sc.meshes[vb == sc.ids[0] ? 1 : 0];
      all_pairs += cs.vertices.size() * cs.triangles.size();
      for (Index v : cs.vertices)
        for (Index t : cs.triangles) {
          const Triangle& tri = tm.triangles[t];
          if (testkit::pointTriangleDistance(vm.vertices[v], tm.vertices[tri[0]], tm.vertices[tri[1]],
                                          tm.vertices[tri[2]]) < 2 * margin) {
            ++near;
            EXPECT_TRUE(cand.count({vb, v, tb, t})) << "vertex " << v << " triangle " << t;
          }
        }
    }
  EXPECT_GT(near, 20u);
  // The pair grid visits far fewer (vertex, triangle) entries than the |V|·|T| product.
  const std::size_t linear = res.stats.candidate_vertices + res.stats.candidate_triangles + res.stats.candidate_pairs;
  std::cout << "[ candidates ] probes " << res.stats.candidate_probes << ", |V|+|T|+found " << linear
            << ", |V|x|T| " << all_pairs << "\n";
  EXPECT_LT(res.stats.candidate_probes, all_pairs / 10);
  EXPECT_LT(res.stats.candidate_probes, 40 * linear);
}

TEST(Candidates, ContainEveryNearPairOfTheFlaggedSetsWithoutAllPairsLoop) {
  checkCandidates(Flagging::SensorsAndBounds);
}

TEST(Candidates, ThesisModeSetsAndPairGridToo) { checkCandidates(Flagging::Sensors); }

// The thesis mode alone (no bounds layer) on its own chapter-4 cases: the sensors must flag each
// scene, and the fraction of contacts in sensor-flagged sets must not fall below today's: all of
// them for two spheres, half for three in a row (the middle sphere's particles flag one of its
// two contacts; the bounds layer of the default mode exists for this).
TEST(Chapter4, ThesisModeAlone) {
  SensorSettings s;
  s.flagging = Flagging::Sensors;
  for (int scene = 0; scene < 2; ++scene) {
    Scene sc(s);
    TriMesh a = makeSphere(1.0, 600), b = makeSphere(1.0, 600), c = makeSphere(1.0, 600);
    const double gap = 0.3 * meanEdge(a);
    b.translate(Vec3(2.0 + gap, 0, 0));
    c.translate(Vec3(4.0 + 2 * gap, 0, 0));
    sc.meshes = {a, b};
    if (scene == 1) sc.meshes.push_back(c);
    sc.registerAll(0.4 * meanEdge(a));
    const StepResult* res = nullptr;
    for (int k = 0; k < 3; ++k) {
      res = &sc.world.step();
      EXPECT_EQ(res->stats.round_cap_hits, 0u);
    }
    const CoverageReport cov = coverage(sc, *res, sc.world.mu(sc.ids[0], sc.ids[1]));
    std::cout << "[ thesis mode ] " << sc.meshes.size() << " spheres: " << cov.in_sets << " of " << cov.truth
              << " contacts within mu lie in sensor-flagged sets\n";
    EXPECT_GT(res->stats.flagged_by_sensors, 0u);
    EXPECT_GT(cov.truth, 0u);
    if (scene == 0) {
      EXPECT_EQ(cov.in_sets, cov.truth) << "thesis case 1 must be complete";
    } else {
      EXPECT_GE(2 * cov.in_sets, cov.truth) << "measured 1672 of 3344";
    }
  }
}

TEST(World, FarApartBodiesFlagNothing) {
  Scene sc;
  TriMesh a = makeSphere(1.0, 300), b = makeSphere(1.0, 300);
  b.translate(Vec3(5, 0, 0));
  sc.meshes = {a, b};
  sc.registerAll(0.01);
  const StepResult& res = sc.world.step();
  EXPECT_EQ(res.flagged.size(), 0u);
  EXPECT_EQ(res.candidates.size(), 0u);
  EXPECT_EQ(res.stats.particles, 2u);  // two convex bodies: one particle each (thesis §3.1)
}

TEST(World, DeterministicBitForBit) {
  auto run = [] {
    Scene sc;
    TriMesh a = makeSphere(1.0, 800), b = makeTorus(0.8, 0.3, 800), c = makeSphere(0.6, 400);
    b.translate(Vec3(1.9, 0, 0));
    c.translate(Vec3(0, 1.55, 0.2));
    sc.meshes = {a, b, c};
    sc.registerAll(0.02);
    std::vector<FlaggedPair> flagged;
    std::vector<CandidatePair> cands;
    std::vector<ParticleState> parts;
    for (int s = 0; s < 8; ++s) {
      for (Vec3& p : sc.meshes[1].vertices) p.x() -= 0.01;  // b approaches a
      const StepResult& r = sc.world.step();
      flagged.insert(flagged.end(), r.flagged.begin(), r.flagged.end());
      cands.insert(cands.end(), r.candidates.begin(), r.candidates.end());
    }
    for (const ParticleState& p : sc.world.particles()) parts.push_back(p);
    return std::make_tuple(flagged, cands, parts.size(), parts.empty() ? 0u : parts.back().vertex);
  };
  const auto r1 = run();
  const auto r2 = run();
  EXPECT_GT(std::get<0>(r1).size(), 0u);
  EXPECT_TRUE(std::get<0>(r1) == std::get<0>(r2));
  EXPECT_TRUE(std::get<1>(r1) == std::get<1>(r2));
  EXPECT_EQ(std::get<2>(r1), std::get<2>(r2));
  EXPECT_EQ(std::get<3>(r1), std::get<3>(r2));
}

// Two bodies closing in while the first stretches (so the repartition checks, which ride on the
// refit, fire on the way), with previous positions (the motion term). `ahead`: refitNow for every
// body before each step, as a physics engine's solver hook does. Returns everything step() gave.
struct RefitTrace {
  std::vector<std::vector<CandidatePair>> candidates;
  std::vector<std::vector<FlaggedPair>> flagged;
  std::vector<std::size_t> repartitions;
  std::size_t refit_now_true = 0;
};

RefitTrace runRefitScene(bool ahead) {
  SensorSettings s;
  s.repartition.check_every = 3;
  Scene sc(s);
  TriMesh a = makeSphere(1.0, 900), b = makeTorus(0.8, 0.3, 900);
  b.translate(Vec3(2.3, 0.1, 0));
  sc.meshes = {a, b, a, b};  // 2 and 3: the previous positions of 0 and 1
  std::vector<BodyId> ids;
  for (std::size_t i = 0; i < 2; ++i) {
    BodyDesc d;
    d.triangles = sc.meshes[i].triangles;
    d.positions = PositionView::of(sc.meshes[i].vertices);
    d.previous = PositionView::of(sc.meshes[i + 2].vertices);
    d.margin = 0.02;
    ids.push_back(sc.world.addBody(d));
  }
  RefitTrace t;
  EXPECT_FALSE(sc.world.refitNow(ids[0])) << "a body step() has not partitioned yet";
  const std::vector<Vec3> rest = sc.meshes[0].vertices;
  for (int step = 0; step < 24; ++step) {
    for (std::size_t i = 0; i < 2; ++i) sc.meshes[i + 2].vertices = sc.meshes[i].vertices;
    for (std::size_t v = 0; v < rest.size(); ++v)
      sc.meshes[0].vertices[v] = Vec3(rest[v].x() * (1.0 + 0.04 * step), rest[v].y(), rest[v].z());
    for (Vec3& p : sc.meshes[1].vertices) p.x() -= 0.02;
    if (ahead) {
      for (BodyId id : ids) t.refit_now_true += sc.world.refitNow(id) ? 1 : 0;
    }
    const StepResult& r = sc.world.step();
    t.candidates.push_back(r.candidates);
    t.flagged.push_back(r.flagged);
    t.repartitions.push_back(r.stats.repartitions);
  }
  return t;
}

TEST(RefitNow, SameResultsAsTheStepsOwnRefit) {
  const RefitTrace in_step = runRefitScene(false);
  const RefitTrace ahead = runRefitScene(true);
  EXPECT_EQ(ahead.refit_now_true, 2u * 23u) << "every step after the first refits both bodies ahead";
  std::size_t candidates = 0, repartitions = 0;
  for (std::size_t s = 0; s < in_step.candidates.size(); ++s) {
    EXPECT_TRUE(in_step.candidates[s] == ahead.candidates[s]) << "step " << s;
    EXPECT_TRUE(in_step.flagged[s] == ahead.flagged[s]) << "step " << s;
    EXPECT_EQ(in_step.repartitions[s], ahead.repartitions[s]) << "step " << s;
    candidates += in_step.candidates[s].size();
    repartitions += in_step.repartitions[s];
  }
  EXPECT_GT(candidates, 100u) << "the bodies must meet, or the comparison proves little";
  EXPECT_GE(repartitions, 1u) << "the stretch must repartition, so that the checks are compared too";
}

TEST(RefitNow, NewPositionsCancelIt) {
  // refitNow, then the owner hands over other memory with the bodies in contact: step() must
  // refit from the new positions, not keep the boxes of the old ones (which are far apart).
  auto run = [](bool ahead) {
    Scene sc;
    TriMesh a = makeSphere(1.0, 600), far = makeSphere(1.0, 600), near = makeSphere(1.0, 600);
    far.translate(Vec3(5.0, 0, 0));
    near.translate(Vec3(1.99, 0, 0));
    sc.meshes = {a, far, near};
    std::vector<BodyId> ids;
    for (std::size_t i = 0; i < 2; ++i) {
      BodyDesc d;
      d.triangles = sc.meshes[i].triangles;
      d.positions = PositionView::of(sc.meshes[i].vertices);
      d.margin = 0.02;
      ids.push_back(sc.world.addBody(d));
    }
    sc.world.step();
    if (ahead) {
      EXPECT_TRUE(sc.world.refitNow(ids[1]));
    }
    sc.world.setPositions(ids[1], PositionView::of(sc.meshes[2].vertices));
    return sc.world.step().candidates;
  };
  const std::vector<CandidatePair> plain = run(false);
  EXPECT_GT(plain.size(), 0u);
  EXPECT_TRUE(run(true) == plain);
  SensorWorld empty;
  EXPECT_THROW(empty.refitNow(7), Error);
}

// Runs `steps` steps with `deform` applied to body 0 before each; returns its repartition count.
std::size_t repartitionsAfter(AreaEstimator est, const std::function<void(std::vector<Vec3>&, int)>& deform) {
  SensorSettings s;
  s.repartition.estimator = est;
  s.repartition.check_every = 1;
  s.repartition.edge_stretch_trigger = 0.0;  // isolate the area estimators
  Scene sc(s);
  TriMesh a = makeSphere(1.0, 1000), b = makeSphere(1.0, 1000);
  b.translate(Vec3(3, 0, 0));
  sc.meshes = {a, b};
  BodyDesc d;
  for (std::size_t i = 0; i < 2; ++i) {
    d.triangles = sc.meshes[i].triangles;
    d.positions = PositionView::of(sc.meshes[i].vertices);
    d.particles = 8;  // several regions so the walk has room
    sc.ids.push_back(sc.world.addBody(d));
  }
  sc.world.step();
  const std::vector<Vec3> rest = sc.meshes[0].vertices;
  for (int step = 1; step <= 10; ++step) {
    sc.meshes[0].vertices = rest;
    deform(sc.meshes[0].vertices, step);
    sc.world.step();
  }
  return sc.world.repartitionCount(sc.ids[0]);
}

TEST(Repartition, StretchTriggersRigidMotionDoesNot) {
  for (AreaEstimator est : {AreaEstimator::TrueArea, AreaEstimator::FourDirectionWalk}) {
    const char* name = est == AreaEstimator::TrueArea ? "true area" : "four-direction walk";
    const std::size_t rigid = repartitionsAfter(est, [](std::vector<Vec3>& p, int step) {
      const Eigen::AngleAxisd rot(0.15 * step, Vec3(0.2, 1.0, 0.4).normalized());
      for (Vec3& x : p) x = rot * x + Vec3(0.05 * step, -0.02 * step, 0.0);
    });
    EXPECT_EQ(rigid, 0u) << name;
    const std::size_t stretched = repartitionsAfter(est, [](std::vector<Vec3>& p, int step) {
      const double f = 1.0 + 0.25 * step;  // reaches 3.5× along x and 1.75× along y
      for (Vec3& x : p) x = Vec3(x.x() * f, x.y() * (1.0 + 0.075 * step), x.z());
    });
    EXPECT_GE(stretched, 1u) << name;
  }
}

TEST(Repartition, EdgeStretchTriggersAndRefreshesMu) {
  // μ decides only in the thesis's flag-only mode; the default midphase does not read it, and
  // there an edge stretch alone repartitions nothing.
  for (Flagging mode : {Flagging::Sensors, Flagging::SensorsAndBounds}) {
    SensorSettings s;
    s.flagging = mode;
    s.repartition.check_every = 1;
    s.repartition.area_trigger = 1e9;  // only the edge trigger can fire
    Scene sc(s);
    TriMesh a = makeSphere(1.0, 500), b = makeSphere(1.0, 500);
    b.translate(Vec3(3, 0, 0));
    sc.meshes = {a, b};
    sc.registerAll(0.0);
    sc.world.step();
    const double mu0 = sc.world.mu(sc.ids[0], sc.ids[1]);
    for (Vec3& x : sc.meshes[0].vertices) x *= 2.0;
    sc.world.step();
    if (mode == Flagging::Sensors) {
      EXPECT_EQ(sc.world.repartitionCount(sc.ids[0]), 1u);
      EXPECT_EQ(sc.world.repartitionCount(sc.ids[1]), 0u) << "only the body that needs it";
      EXPECT_NEAR(sc.world.mu(sc.ids[0], sc.ids[1]), 2.0 * mu0, 1e-9);
    } else {
      EXPECT_EQ(sc.world.repartitionCount(sc.ids[0]), 0u);
    }
  }
}

TEST(Repartition, WalkEstimatorMatchesRectangleOnPatch) {
  // A flat grid patch in one region: the walk spans the whole patch, so the estimate is the
  // patch's area (up to the grid spacing).
  const TriMesh p = makePatch(2.0, 1.0, 21, 11);
  MeshTopology topo(p.triangles, p.vertices.size());
  Partition part;
  part.region_of.assign(p.vertices.size(), 0);
  part.seed_vertex = {static_cast<Index>(5 * 21 + 10)};  // the centre vertex
  EXPECT_NEAR(regionAreaWalk(topo, PositionView::of(p.vertices), part, part.seed_vertex[0]), 2.0, 1e-9);
  EXPECT_NEAR(regionAreasTrue(topo, PositionView::of(p.vertices), part)[0], 2.0, 1e-9);
}

using test::messageOf;

TEST(WorldErrors, BadBodiesAreNamed) {
  SensorWorld w;
  TriMesh m = makeSphere(1.0, 100);
  BodyDesc d;
  d.triangles = m.triangles;
  d.positions = PositionView::of(m.vertices);
  d.name = "ball";
  d.margin = -1.0;
  EXPECT_NE(messageOf([&] { w.addBody(d); }).find("margin"), std::string::npos);
  d.margin = 0.0;
  d.particles = 100000;
  EXPECT_NE(messageOf([&] { w.addBody(d); }).find("particles"), std::string::npos);
  d.particles = 0;
  d.triangles.push_back({0, 1, 100000});
  const std::string idx = messageOf([&] { w.addBody(d); });
  EXPECT_NE(idx.find("ball"), std::string::npos) << idx;
  EXPECT_NE(idx.find("out of range"), std::string::npos) << idx;
  d.triangles = m.triangles;
  std::vector<Vec3> flat(m.vertices.size(), Vec3(1, 2, 3));
  d.positions = PositionView::of(flat);
  EXPECT_NE(messageOf([&] { w.addBody(d); }).find("degenerate"), std::string::npos);
  EXPECT_NE(messageOf([&] { w.removeBody(42); }).find("unknown body"), std::string::npos);
  EXPECT_EQ(w.bodyIds().size(), 0u) << "nothing half-added";
}

TEST(WorldErrors, SettingsOutOfRangeAreNamed) {
  SensorSettings s;
  s.mu_edge_factor = 0.2;
  EXPECT_NE(messageOf([&] { SensorWorld w(s); }).find("mu_edge_factor"), std::string::npos);
  s = {};
  s.r_eff = -1;
  EXPECT_NE(messageOf([&] { SensorWorld w(s); }).find("r_eff"), std::string::npos);
  s = {};
  s.max_rounds = 0;
  EXPECT_NE(messageOf([&] { SensorWorld w(s); }).find("max_rounds"), std::string::npos);
  s = {};
  s.repartition.area_trigger = 0.5;
  EXPECT_NE(messageOf([&] { SensorWorld w(s); }).find("area_trigger"), std::string::npos);
  s = {};
  s.partition.normal_weight = std::numeric_limits<double>::quiet_NaN();
  EXPECT_NE(messageOf([&] { SensorWorld w(s); }).find("normal_weight"), std::string::npos);
}

TEST(WorldErrors, PositionsTurningNaNDuringSimulationAreReported) {
  Scene sc;
  TriMesh a = makeSphere(1.0, 200), b = makeSphere(1.0, 200);
  b.translate(Vec3(2.05, 0, 0));
  sc.meshes = {a, b};
  sc.registerAll(0.01);
  sc.world.step();
  sc.meshes[1].vertices[7].x() = std::numeric_limits<double>::quiet_NaN();
  const std::string msg = messageOf([&] { sc.world.step(); });
  EXPECT_NE(msg.find("mesh1"), std::string::npos) << msg;
  EXPECT_NE(msg.find("vertex 7"), std::string::npos) << msg;
}

}  // namespace
}  // namespace psc

namespace psc {
namespace {

// The sensors earn their place: on curved contact along a diagonal (where axis-aligned boxes are
// loosest) the sensor axis drops pairs the boxes keep, and no pair within the contact radius.
TEST(SensorDecision, ObliqueCurvedContactSameCandidatesFewerProbes) {
  const auto run = [](Flagging mode) {
    SensorSettings s;
    s.flagging = mode;
    Scene sc(s);
    TriMesh a = makeSphere(1.0, 2000), b = makeSphere(0.7, 1200);
    const double margin = 0.3 * meanEdge(a);
    const Vec3 dir = Vec3(1, 1, 1).normalized();
    b.rotate(Vec3(0.2, 1, 0.4), 0.9).translate((1.7 + margin) * dir);
    sc.meshes = {a, b};
    sc.registerAll(margin);
    const StepResult* res = nullptr;
    for (int k = 0; k < 3; ++k) res = &sc.world.step();
    std::set<std::tuple<BodyId, Index, BodyId, Index>> cand;
    for (const CandidatePair& c : res->candidates) cand.insert({c.vertex_body, c.vertex, c.triangle_body, c.triangle});
    std::size_t truth = 0, found = 0;
    for (int i = 0; i < 2; ++i)
      for (const auto& [v, t] : testkit::bruteContacts(sc.meshes[i], sc.meshes[1 - i], 2.0 * margin)) {
        ++truth;
        found += cand.count({sc.ids[i], v, sc.ids[1 - i], t});
      }
    return std::make_tuple(res->candidates.size(), truth, found, res->stats);
  };
  const auto [n_sensors, truth_s, found_s, st_s] = run(Flagging::SensorsAndBounds);
  const auto [n_bounds, truth_b, found_b, st_b] = run(Flagging::Bounds);
  std::cout << "[ sensor decision ] candidates: sensors " << n_sensors << ", bounds " << n_bounds << "; contacts "
            << found_s << "/" << truth_s << "; vertices dropped by the slab " << st_s.vertices_dropped
            << ", chunks dropped " << st_s.chunks_dropped << "; probes sensors " << st_s.candidate_probes
            << ", bounds " << st_b.candidate_probes << "\n";
  ASSERT_GT(truth_s, 20u) << "the scene must touch";
  EXPECT_EQ(found_s, truth_s);
  EXPECT_EQ(found_b, truth_b);
  // The exact distance keeps exactly the pairs within the radius, with or without the sensor
  // stage: what the sensors cut is the work of finding them.
  EXPECT_EQ(n_sensors, truth_s);
  EXPECT_EQ(n_bounds, truth_b);
  EXPECT_LT(st_s.candidate_probes, st_b.candidate_probes) << "the sensors must cut probes on oblique curved contact";
  EXPECT_GT(st_s.vertices_dropped + st_s.chunks_dropped, 0u);
  EXPECT_EQ(st_b.vertices_dropped + st_b.chunks_dropped + st_b.region_pairs_separated, 0u) << "Bounds: no sensor stage";
}

// The candidate stage's two probe paths, AVX2 (four boxes at a time, where the processor has it)
// and SSE2 (two), give the same candidates bit for bit, after the same vertex picks (the slab drops
// the same vertices) and the same kept triangles (the same probes): three bodies pressed into each
// other over a few steps, with a motion term, in both modes that probe.
TEST(Probes, Avx2AndSse2GiveTheSameCandidates) {
  if (!detail::avx2ProbesAvailable()) GTEST_SKIP() << "no AVX2 on this processor: only the SSE2 path runs";
  const auto run = [](Flagging flagging, bool avx2) {
    detail::allowAvx2Probes(avx2);
    SensorSettings settings;
    settings.flagging = flagging;
    Scene sc(settings);
    TriMesh a = makeSphere(1.0, 900), b = makeTorus(0.8, 0.3, 900), c = makeSphere(0.6, 500);
    b.translate(Vec3(1.85, 0.05, 0));
    c.translate(Vec3(0.1, 1.5, 0.2));
    sc.meshes = {a, b, c};
    sc.registerAll(0.03);
    std::vector<CandidatePair> candidates;
    std::size_t probes = 0, dropped = 0;
    for (int s = 0; s < 6; ++s) {
      for (Vec3& p : sc.meshes[1].vertices) p.x() -= 0.02;
      for (Vec3& p : sc.meshes[2].vertices) p.y() -= 0.015;
      const StepResult& r = sc.world.step();
      candidates.insert(candidates.end(), r.candidates.begin(), r.candidates.end());
      probes += r.stats.candidate_probes;
      dropped += r.stats.vertices_dropped;
    }
    detail::allowAvx2Probes(true);
    return std::make_tuple(candidates, probes, dropped);
  };
  for (Flagging flagging : {Flagging::SensorsAndBounds, Flagging::Bounds}) {
    const auto [wide, wide_probes, wide_dropped] = run(flagging, true);
    const auto [narrow, narrow_probes, narrow_dropped] = run(flagging, false);
    ASSERT_GT(wide.size(), 100u);
    EXPECT_GT(wide_probes, wide.size());
    EXPECT_EQ(wide_probes, narrow_probes);
    EXPECT_EQ(wide_dropped, narrow_dropped);
    if (flagging == Flagging::SensorsAndBounds) {
      EXPECT_GT(wide_dropped, 0u) << "the slab must drop vertices here";
    }
    EXPECT_TRUE(wide == narrow);
  }
}

// SensorSettings::nearest_candidates keeps, of each vertex's candidates against one body, exactly
// those within a relative 1e-4 of its nearest by the filter's distance (2.1e-4 on the squares), in
// the order of the full set, and counts those it measured and left out: three bodies pressed into
// each other over a few steps, with and without the sensor stage. From the second step on, the
// search of the vertices in contact starts from their last step's nearest triangles (counted in
// nearest_seeded), which must change no candidate; the torus's mesh replaced by a renumbering of
// itself drops the seeds against it for one step.
TEST(Candidates, NearestCandidatesKeepEachVertexsNearestTriangles) {
  for (Flagging flagging : {Flagging::SensorsAndBounds, Flagging::Bounds}) {
    const auto run = [&](bool nearest) {
      SensorSettings settings;
      settings.flagging = flagging;
      settings.nearest_candidates = nearest;
      auto sc = std::make_unique<Scene>(settings);
      TriMesh a = makeSphere(1.0, 900), b = makeTorus(0.8, 0.3, 900), c = makeSphere(0.6, 500);
      b.translate(Vec3(1.85, 0.05, 0));
      c.translate(Vec3(0.1, 1.5, 0.2));
      sc->meshes = {a, b, c};
      sc->registerAll(0.03);
      std::vector<std::vector<CandidatePair>> steps;
      std::vector<std::size_t> dropped, seeded;
      std::vector<std::vector<TriMesh>> shapes;  // the meshes at each step
      for (int s = 0; s < 4; ++s) {
        for (Vec3& p : sc->meshes[1].vertices) p.x() -= 0.02;
        for (Vec3& p : sc->meshes[2].vertices) p.y() -= 0.015;
        if (s == 2) {
          // The torus's mesh replaced by itself, triangles listed backwards with their corners
          // turned: the chunks are rebuilt, and the seeds against the torus must be dropped.
          std::vector<Triangle>& tris = sc->meshes[1].triangles;
          std::reverse(tris.begin(), tris.end());
          for (Triangle& t : tris) t = Triangle{t[1], t[2], t[0]};
          sc->world.replaceMesh(sc->ids[1], tris, PositionView::of(sc->meshes[1].vertices));
        }
        const StepResult& r = sc->world.step();
        steps.push_back(r.candidates);
        dropped.push_back(r.stats.candidates_not_nearest);
        seeded.push_back(r.stats.nearest_seeded);
        shapes.push_back(sc->meshes);
      }
      return std::make_tuple(std::move(sc), steps, dropped, shapes, seeded);
    };
    const auto [full_scene, full, full_dropped, shapes, full_seeded] = run(false);
    const auto [near_scene, near, near_dropped, near_shapes, near_seeded] = run(true);
    std::map<BodyId, std::size_t> index;
    for (std::size_t i = 0; i < full_scene->ids.size(); ++i) index[full_scene->ids[i]] = i;
    std::size_t kept_total = 0, full_total = 0;
    for (std::size_t s = 0; s < full.size(); ++s) {
      EXPECT_EQ(full_dropped[s], 0u);
      const std::vector<TriMesh>& meshes = shapes[s];  // the same positions in both runs
      // Least squared distance per (vertex body, vertex, triangle body) over the full set.
      const auto d2 = [&](const CandidatePair& c) {
        const TriMesh& vm = meshes[index.at(c.vertex_body)];
        const TriMesh& tm = meshes[index.at(c.triangle_body)];
        const Triangle& t = tm.triangles[c.triangle];
        return detail::filterDistance2(vm.vertices[c.vertex], tm.vertices[t[0]], tm.vertices[t[1]], tm.vertices[t[2]]);
      };
      std::map<std::tuple<BodyId, Index, BodyId>, double> least;
      for (const CandidatePair& c : full[s]) {
        const auto key = std::make_tuple(c.vertex_body, c.vertex, c.triangle_body);
        const auto it = least.find(key);
        if (it == least.end() || d2(c) < it->second) least[key] = d2(c);
      }
      std::vector<CandidatePair> expected;
      for (const CandidatePair& c : full[s])
        if (d2(c) <= least[std::make_tuple(c.vertex_body, c.vertex, c.triangle_body)] * (1.0 + 2.1e-4)) expected.push_back(c);
      EXPECT_TRUE(near[s] == expected) << "step " << s << ": " << near[s].size() << " against " << expected.size();
      // Counted: the pairs measured and left out; the probes skip others for a vertex whose nearest
      // is already known.
      EXPECT_LE(near_dropped[s], full[s].size() - near[s].size());
      EXPECT_GT(near_dropped[s], 0u);
      EXPECT_EQ(full_seeded[s], 0u);
      if (s == 0) EXPECT_EQ(near_seeded[s], 0u);
      else if (s == 2) {
        // Only the sphere–sphere contact keeps its seeds across the torus's new mesh.
        EXPECT_GT(near_seeded[s], 0u);
        EXPECT_LT(near_seeded[s], near_seeded[1]);
      } else {
        EXPECT_GT(near_seeded[s], 50u) << "step " << s << ": the vertices in contact start from their nearest";
      }
      kept_total += near[s].size();
      full_total += full[s].size();
    }
    ASSERT_GT(full_total, 3 * kept_total) << "the scene must give vertices several triangles within reach";
    EXPECT_GT(kept_total, 100u);
  }
}

// The candidate filter's branch-free distance on seeded random pairs: general triangles, slivers,
// collinear and coincident corners; points anywhere, on the plane inside, on an edge's line, at a
// corner and just above the plane. On well-shaped triangles it is the reference point-triangle
// distance (testkit, by Voronoi regions) up to rounding. On every triangle it never exceeds the
// distance to the nearest edge (an upper bound of the true distance), and a point on or just above
// a sliver is found that close (the reference's Voronoi regions lose it there: 8e-7 for a point
// 1e-10 above the sliver). Its four-lane form gives the same bits with and without AVX2.
TEST(Probes, FilterDistanceMatchesTheReferenceAndTheLanesAgree) {
  std::mt19937_64 rng(20261125);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  const auto point = [&] { return Vec3(u(rng), u(rng), u(rng)); };
  const auto edge2 = [](const Vec3& p, const Vec3& x, const Vec3& y) {
    const Vec3 d = y - x;
    const double l2 = d.squaredNorm();
    const double t = l2 > 0.0 ? std::clamp((p - x).dot(d) / l2, 0.0, 1.0) : 0.0;
    return (p - (x + t * d)).squaredNorm();
  };
  std::vector<std::array<Vec3, 4>> cases;  // p, a, b, c
  std::size_t well_shaped = 0;
  for (int i = 0; i < 4000; ++i) {
    Vec3 a = point(), b = point(), c = point();
    const int shape = i % 8, place = i % 5;
    switch (shape) {
      case 1: c = a + 0.37 * (b - a); break;                 // collinear
      case 2: b = a; break;                                   // two corners coincide
      case 3: b = a; c = a; break;                            // a point
      case 4: c = 0.5 * (a + b) + 1e-7 * point(); break;      // a sliver
      default: break;
    }
    const Vec3 n = (b - a).cross(c - a);
    Vec3 p = point();
    switch (place) {
      case 1: p = a + 0.3 * (b - a) + 0.2 * (c - a); break;                 // on the plane, inside
      case 2: p = a + 1.7 * (b - a); break;                                 // on an edge's line, beyond
      case 3: p = b; break;                                                 // at a corner
      case 4: p = a + 0.3 * (b - a) + 0.2 * (c - a) + 1e-3 * n; break;     // just above, inside
      default: break;
    }
    cases.push_back({p, a, b, c});
    const double d = detail::filterDistance2(p, a, b, c);
    const double scale = 1e-12 * (1.0 + (p - a).squaredNorm());
    ASSERT_TRUE(std::isfinite(d) && d >= 0.0) << "case " << i;
    EXPECT_LE(d, std::min({edge2(p, a, b), edge2(p, b, c), edge2(p, c, a)}) + scale) << "case " << i;
    // Up to the rounding of p and of the plane's normal (a sliver's is known to about 1e-9).
    if (place == 1 || place == 4) {
      EXPECT_LE(d, 1e-6 * n.squaredNorm() * (1.0 + 1e-6) + 1e-16) << "case " << i;
    }
    const double sin2 = n.squaredNorm() / std::max((b - a).squaredNorm() * (c - a).squaredNorm(), 1e-300);
    if (sin2 > 1e-6 && n.squaredNorm() / std::max({(b - a).squaredNorm(), (c - b).squaredNorm(), (a - c).squaredNorm()}) > 1e-8) {
      ++well_shaped;
      EXPECT_NEAR(d, testkit::pointTriangleDistanceSquared(p, a, b, c), scale) << "case " << i;
    }
  }
  EXPECT_GT(well_shaped, 1500u);
  std::vector<double> one(cases.size());
  for (std::size_t i = 0; i < cases.size(); ++i)
    one[i] = detail::filterDistance2(cases[i][0], cases[i][1], cases[i][2], cases[i][3]);
  for (bool avx2 : {true, false}) {
    if (avx2 && !detail::avx2ProbesAvailable()) continue;
    detail::allowAvx2Probes(avx2);
    for (std::size_t i = 0; i + 4 <= cases.size(); i += 4) {
      const Vec3 *p[4], *a[4], *b[4], *c[4];
      for (int l = 0; l < 4; ++l) {
        p[l] = &cases[i + l][0];
        a[l] = &cases[i + l][1];
        b[l] = &cases[i + l][2];
        c[l] = &cases[i + l][3];
      }
      double out[4];
      detail::filterDistance2x4(p, a, b, c, out);
      for (int l = 0; l < 4; ++l)
        ASSERT_EQ(std::memcmp(&out[l], &one[i + l], sizeof(double)), 0)
            << "case " << i + l << (avx2 ? " (AVX2)" : " (portable)") << ": " << out[l] << " vs " << one[i + l];
    }
    detail::allowAvx2Probes(true);
  }
}

}  // namespace
}  // namespace psc
