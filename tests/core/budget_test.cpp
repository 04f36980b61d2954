#include "psc/budget.h"
#include "psc/error.h"
#include "psc/mesh.h"
#include "psc/shapes.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>

namespace psc {
namespace {

constexpr double kPi = 3.14159265358979323846;

ConvexParts decompose(const TriMesh& m, const DecompositionSettings& s = {}) {
  const MeshTopology topology(m.triangles, m.vertices.size());
  return decomposeConvex(topology, PositionView::of(m.vertices), s);
}

// The header's formula, computed independently with the trigonometric functions.
double shadowCapReal(double big, double small) {
  const double theta = std::asin(small / (big + small));
  const double eta = 12.0 * (1.0 - std::cos(kPi / 6.0)) / 2.0;
  return eta * 2.0 / (1.0 - std::cos(theta));
}

BudgetBody bodyOf(const ConvexParts& parts) { return BudgetBody{parts, 0}; }

TEST(Budget, ShadowCapBoundClosedForm) {
  // θ = 30° exactly when R = r: 2/(1 − cos 30°) ≈ 14.93 caps, times η = 12·(1 − cos 30°)/2 = 12.
  EXPECT_NEAR(shadowCapReal(1.0, 1.0), 12.0, 1e-9);
  EXPECT_EQ(shadowCapBound(1.0, 1.0), 12u);
  EXPECT_EQ(shadowCapBound(0.37, 0.37), 12u);
  EXPECT_EQ(shadowCapBound(1e6, 1e6), 12u);
  for (double ratio : {1.5, 2.0, 4.0, 10.0, 33.0, 100.0, 1000.0}) {
    EXPECT_EQ(shadowCapBound(ratio, 1.0), static_cast<std::size_t>(std::floor(shadowCapReal(ratio, 1.0))))
        << ratio;
  }
  // R ≫ r: sin θ ≈ r/(R + r), 1 − cos θ ≈ sin²θ / 2, so A/B·η ≈ 4·η·((R + r)/r)².
  const double eta = 6.0 * (1.0 - std::sqrt(3.0) / 2.0);
  const double big = double(shadowCapBound(1000.0, 1.0));
  EXPECT_NEAR(big / (4.0 * eta * 1001.0 * 1001.0), 1.0, 1e-3);
  // Growing with R, never below 1 even when the part is much smaller than the smallest "other".
  std::size_t previous = 0;
  for (double r = 0.01; r < 50.0; r *= 1.3) {
    const std::size_t b = shadowCapBound(r, 1.0);
    EXPECT_GE(b, previous);
    EXPECT_GE(b, 1u);
    previous = b;
  }
  EXPECT_EQ(shadowCapBound(1e-6, 1.0), 1u);
  EXPECT_THROW(shadowCapBound(0.0, 1.0), Error);
  EXPECT_THROW(shadowCapBound(1.0, -1.0), Error);
  EXPECT_THROW(shadowCapBound(std::nan(""), 1.0), Error);
}

TEST(Budget, ConvexBodiesAreOnePart) {
  EXPECT_EQ(decompose(makeSphere(1.0, 500)).parts.size(), 1u);
  EXPECT_EQ(decompose(makeSphere(1.0, 100)).parts.size(), 1u);  // small enough for HACD directly
  EXPECT_EQ(decompose(makeIcosphere(2.0, 3)).parts.size(), 1u);
  EXPECT_EQ(decompose(makeBox(Vec3(1.0, 0.5, 2.0), 600)).parts.size(), 1u);
  EXPECT_EQ(decompose(makeBox(Vec3(2.0, 2.0, 0.1), 300)).parts.size(), 1u);
  EXPECT_EQ(decompose(makePatch(2.0, 1.0, 12, 8)).parts.size(), 1u);  // flat: convex in the limit
}

TEST(Budget, ConcaveBodiesAreSeveralParts) {
  for (std::size_t n : {150u, 2000u}) {
    const ConvexParts torus = decompose(makeTorus(1.0, 0.3, n));
    EXPECT_GE(torus.parts.size(), 4u) << n;
    const ConvexParts u = decompose(makeUShape(2.0, 1.5, 0.3, n));
    EXPECT_GE(u.parts.size(), 3u) << n;
    const ConvexParts fork = decompose(makeFork(4.0, 0.2, n));
    // The fork's crotch has coincident vertices; merged, they make a non-manifold proxy that is
    // kept away from HACD (whose hull code double-frees on such input, see safeForHacd), so the
    // fork is one part per connected piece: a known weakness, not a goal.
    EXPECT_GE(fork.parts.size(), 1u) << n;
    // Parts are smaller than the body.
    for (const ConvexPart& p : torus.parts) EXPECT_LT(p.radius, 1.3);
  }
  // A looser tolerance never needs more parts than a much tighter one on the torus.
  DecompositionSettings loose;
  loose.concavity = 0.2;
  DecompositionSettings tight;
  tight.concavity = 0.02;
  const TriMesh torus = makeTorus(1.0, 0.3, 2000);
  EXPECT_LE(decompose(torus, loose).parts.size(), decompose(torus, tight).parts.size());
}

TEST(Budget, EveryVertexIsLabelledAndInsideItsPart) {
  TriMesh m = makeTorus(1.0, 0.3, 3000);
  m.vertices.push_back(Vec3(1.0, 0.0, 0.05));  // isolated: in no triangle
  const ConvexParts parts = decompose(m);
  ASSERT_EQ(parts.part_of.size(), m.vertices.size());
  std::size_t counted = 0;
  for (const ConvexPart& p : parts.parts) {
    EXPECT_GT(p.vertex_count, 0u);
    counted += p.vertex_count;
  }
  EXPECT_EQ(counted, m.vertices.size());
  for (std::size_t v = 0; v < m.vertices.size(); ++v) {
    ASSERT_LT(parts.part_of[v], parts.parts.size());
    const ConvexPart& p = parts.parts[parts.part_of[v]];
    EXPECT_LE((m.vertices[v] - p.center).norm(), p.radius * (1.0 + 1e-12));
  }
  // The isolated vertex sits next to the ring at angle 0: it joins the part whose centre is nearest.
  const Vec3 lonely = m.vertices.back();
  const Index chosen = parts.part_of.back();
  for (const ConvexPart& p : parts.parts) {
    EXPECT_LE((lonely - parts.parts[chosen].center).norm(), (lonely - p.center).norm() + 1e-12);
  }
}

TEST(Budget, AMinimumPartCountAboveTheVertexCountLabelsEveryVertex) {
  // A review's finding (stop 47): HACD asked for more clusters than the (proxy) mesh has vertices
  // numbers them beyond the vertex count, and the labels' compaction table was sized by the vertex
  // count: a heap overflow (AddressSanitizer) and garbage parts. Small meshes and large ones (whose
  // decimated proxy has about 130 vertices) alike.
  for (const TriMesh& m : {makeTorus(1.0, 0.3, 100), makeUShape(1.0, 1.0, 0.2, 120), makeTorus(1.0, 0.3, 2000)}) {
    for (std::size_t min_parts : {60u, 100u, 140u, 400u}) {
      const MeshTopology topology(m.triangles, m.vertices.size());
      DecompositionSettings settings;
      settings.min_parts = min_parts;
      const ConvexParts parts = decomposeConvex(topology, PositionView::of(m.vertices), settings);
      ASSERT_EQ(parts.part_of.size(), m.vertices.size());
      std::size_t counted = 0;
      for (const ConvexPart& p : parts.parts) counted += p.vertex_count;
      EXPECT_EQ(counted, m.vertices.size()) << m.vertices.size() << " vertices, min_parts " << min_parts;
      for (std::size_t v = 0; v < m.vertices.size(); ++v) {
        ASSERT_LT(parts.part_of[v], parts.parts.size()) << "vertex " << v << ", min_parts " << min_parts;
        const ConvexPart& p = parts.parts[parts.part_of[v]];
        EXPECT_LE((m.vertices[v] - p.center).norm(), p.radius * (1.0 + 1e-12));
      }
    }
  }
}

TEST(Budget, DecompositionIsDeterministic) {
  for (const TriMesh& m : {makeTorus(1.0, 0.3, 5000), makeFork(4.0, 0.2, 800), makeUShape(2.0, 1.5, 0.3, 200)}) {
    const ConvexParts a = decompose(m), b = decompose(m);
    EXPECT_EQ(a.part_of, b.part_of);
    ASSERT_EQ(a.parts.size(), b.parts.size());
    for (std::size_t p = 0; p < a.parts.size(); ++p) {
      EXPECT_EQ(a.parts[p].center, b.parts[p].center);
      EXPECT_EQ(a.parts[p].radius, b.parts[p].radius);
      EXPECT_EQ(a.parts[p].vertex_count, b.parts[p].vertex_count);
    }
  }
}

TEST(Budget, LargeMeshIsDecomposedThroughTheDecimatedCopy) {
  // 50k vertices is far beyond what HACD handles directly (seconds at 1000 triangles): the parts
  // come from the decimated copy and every vertex of the full mesh gets a label. How fast is the
  // benchmark's business; here the result is checked.
  const TriMesh m = makeTorus(1.0, 0.3, 50000);
  const ConvexParts parts = decompose(m);
  ASSERT_EQ(parts.part_of.size(), m.vertices.size());
  // Measured 8 parts around the ring, centres at 0.84–1.04 from the axis, angular gaps ≤ 52°.
  ASSERT_GE(parts.parts.size(), 4u);
  EXPECT_LE(parts.parts.size(), 16u);
  std::vector<std::size_t> labelled(parts.parts.size(), 0);
  for (Index p : parts.part_of) {
    ASSERT_LT(p, parts.parts.size());
    ++labelled[p];
  }
  std::vector<double> angles;
  for (std::size_t p = 0; p < parts.parts.size(); ++p) {
    const ConvexPart& part = parts.parts[p];
    EXPECT_EQ(part.vertex_count, labelled[p]) << "part " << p;
    const double from_axis = std::hypot(part.center.x(), part.center.y());
    EXPECT_GT(from_axis, 0.7) << "part " << p;  // on the tube's core circle (R = 1, r = 0.3)
    EXPECT_LT(from_axis, 1.3) << "part " << p;
    EXPECT_LT(std::abs(part.center.z()), 0.3) << "part " << p;
    angles.push_back(std::atan2(part.center.y(), part.center.x()));
  }
  // The parts go all the way round: no gap of a quarter turn between neighbouring centres.
  std::sort(angles.begin(), angles.end());
  double widest = angles.front() + 2.0 * kPi - angles.back();
  for (std::size_t i = 1; i < angles.size(); ++i) widest = std::max(widest, angles[i] - angles[i - 1]);
  EXPECT_LT(widest, kPi / 2.0);
}

TEST(Budget, TwoConvexBodiesGetOneParticleEach) {
  // Thesis §3.1: two convex objects need one particle each (one other part can touch each).
  const std::vector<BudgetBody> bodies{bodyOf(decompose(makeSphere(1.0, 300))),
                                       bodyOf(decompose(makeBox(Vec3(1, 1, 1), 300)))};
  EXPECT_EQ(particleBudget(bodies), (std::vector<std::size_t>{1, 1}));
}

TEST(Budget, LoneBodyGetsOneParticle) {
  // Nothing else can touch it; its own parts do not count.
  const std::vector<BudgetBody> bodies{bodyOf(decompose(makeTorus(1.0, 0.3, 1000)))};
  ASSERT_GT(bodies[0].parts.parts.size(), 1u);
  EXPECT_EQ(particleBudget(bodies), std::vector<std::size_t>{1});
}

TEST(Budget, ThirteenEqualSpheresGetTwelveEach) {
  // "Equal spheres → 12": at most 12 equal spheres can touch one (the kissing number), so with 12
  // other bodies in the scene the cap of other parts (12) and the shadow-cap bound (12) agree.
  // With only 3 spheres each would get min(12, 2) = 2.
  const ConvexParts sphere = decompose(makeSphere(1.0, 200));
  ASSERT_EQ(sphere.parts.size(), 1u);
  std::vector<BudgetBody> bodies(13, bodyOf(sphere));
  for (std::size_t b : particleBudget(bodies)) EXPECT_EQ(b, 12u);
  bodies.resize(3);
  for (std::size_t b : particleBudget(bodies)) EXPECT_EQ(b, 2u);
}

TEST(Budget, BigBodyBesideSmallOnesGetsMore) {
  const ConvexParts big = decompose(makeSphere(4.0, 400));
  const ConvexParts small = decompose(makeSphere(1.0, 100));
  // Enough small bodies that the cap of other parts does not bind for the big one.
  std::vector<BudgetBody> bodies{bodyOf(big)};
  for (int i = 0; i < 120; ++i) bodies.push_back(bodyOf(small));
  const std::vector<std::size_t> budget = particleBudget(bodies);
  const std::size_t expected_big = shadowCapBound(big.parts[0].radius, small.parts[0].radius);
  EXPECT_EQ(budget[0], expected_big);
  EXPECT_GT(expected_big, 12u);
  EXPECT_EQ(budget[1], 12u);  // equal to the smallest: the kissing number
  EXPECT_GT(budget[0], budget[1]);
}

TEST(Budget, ConcaveBodyGetsAParticlePerPartAtLeast) {
  const ConvexParts torus = decompose(makeTorus(1.0, 0.3, 2000));
  ASSERT_GE(torus.parts.size(), 4u);
  std::vector<BudgetBody> bodies{bodyOf(torus)};
  for (int i = 0; i < 20; ++i) bodies.push_back(bodyOf(decompose(makeSphere(0.3, 100))));
  const std::vector<std::size_t> budget = particleBudget(bodies);
  EXPECT_GE(budget[0], torus.parts.size());
  EXPECT_GT(budget[0], budget[1]);
}

TEST(Budget, OverrideWinsAndVertexCountCaps) {
  const ConvexParts sphere = decompose(makeSphere(1.0, 200));
  std::vector<BudgetBody> bodies(13, bodyOf(sphere));
  bodies[4].override_count = 37;
  const std::vector<std::size_t> budget = particleBudget(bodies);
  EXPECT_EQ(budget[4], 37u);
  EXPECT_EQ(budget[0], 12u);
  // A body with fewer vertices than its bound gets one particle per vertex.
  ConvexParts tiny = sphere;
  tiny.part_of.resize(5);
  bodies.assign(13, bodyOf(sphere));
  bodies[0] = bodyOf(tiny);
  EXPECT_EQ(particleBudget(bodies)[0], 5u);
}

TEST(Budget, RejectsBadInput) {
  const TriMesh m = makeSphere(1.0, 100);
  const MeshTopology topology(m.triangles, m.vertices.size());
  const PositionView view = PositionView::of(m.vertices);
  DecompositionSettings s;
  s.concavity = 0.0;
  EXPECT_THROW(decomposeConvex(topology, view, s), Error);
  s = {};
  s.min_parts = 0;
  EXPECT_THROW(decomposeConvex(topology, view, s), Error);
  s = {};
  s.max_input_triangles = 4;
  EXPECT_THROW(decomposeConvex(topology, view, s), Error);
  std::vector<Vec3> fewer(m.vertices.begin(), m.vertices.end() - 1);
  EXPECT_THROW(decomposeConvex(topology, PositionView::of(fewer), {}), Error);
  std::vector<Vec3> bad = m.vertices;
  bad[7].x() = std::nan("");
  EXPECT_THROW(decomposeConvex(topology, PositionView::of(bad), {}), Error);
  EXPECT_THROW(particleBudget({BudgetBody{}}), Error);
}

}  // namespace
}  // namespace psc
