// The benchmark's ground truth against references: the grid against brute force (random soups and
// real scene states, both radii), and the inside test against shapes whose inside is known. The
// exact distance itself is psc::testkit's, tested in tests/testkit_test.cpp.
#include "bullet_scene.h"
#include "ground_truth.h"
#include "psc/testkit/reference.h"
#include "scenes.h"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>
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

/// The crossing rule of TriangleGrid::rayParityOdd, restated over every triangle of `body`: the
/// ray from p along +axis crosses a triangle whose box it meets (spans p across the axis, reaches
/// p along it) and whose projection holds p, where a point on an edge or vertex shared by two
/// triangles belongs to one of them only, at a hit beyond p.
bool bruteParityOdd(const Vec3& p, const TruthBody& body, int axis) {
  const int u = (axis + 1) % 3, w = (axis + 2) % 3;
  bool odd = false;
  for (const Triangle& t : body.triangles) {
    Vec3 v[3] = {body.x[t[0]], body.x[t[1]], body.x[t[2]]};
    const Vec3 lo = v[0].cwiseMin(v[1]).cwiseMin(v[2]), hi = v[0].cwiseMax(v[1]).cwiseMax(v[2]);
    if (hi[axis] < p[axis] || lo[u] > p[u] || hi[u] < p[u] || lo[w] > p[w] || hi[w] < p[w]) continue;
    const double area = (v[1][u] - v[0][u]) * (v[2][w] - v[0][w]) - (v[1][w] - v[0][w]) * (v[2][u] - v[0][u]);
    if (area == 0.0) continue;
    if (area < 0.0) std::swap(v[1], v[2]);
    double e[3];
    bool holds = true;
    for (int j = 0; j < 3; ++j) {
      const Vec3 &a = v[j], &b = v[(j + 1) % 3];
      const double du = b[u] - a[u], dw = b[w] - a[w];
      e[j] = du * (p[w] - a[w]) - dw * (p[u] - a[u]);
      // On the edge: the triangle holds p only for edges heading to −w (or along +u).
      holds = holds && (e[j] > 0.0 || (e[j] == 0.0 && (dw < 0.0 || (dw == 0.0 && du > 0.0))));
    }
    if (!holds) continue;
    const double hit = (e[1] * v[0][axis] + e[2] * v[1][axis] + e[0] * v[2][axis]) / (e[0] + e[1] + e[2]);
    if (hit > p[axis]) odd = !odd;
  }
  return odd;
}

/// measurePenetration by definition: every vertex of every body strictly inside the box of
/// another closed body's triangles, odd along +x and +y, against every triangle of that body.
Penetration bruteForcePenetration(const std::vector<TruthBody>& bodies) {
  Penetration out;
  for (std::size_t b = 0; b < bodies.size(); ++b) {
    const TruthBody& B = bodies[b];
    if (!B.closed || B.triangles.empty()) continue;
    constexpr double inf = std::numeric_limits<double>::infinity();
    Vec3 lo = Vec3::Constant(inf), hi = Vec3::Constant(-inf);
    for (const Triangle& t : B.triangles)
      for (Index v : t) lo = lo.cwiseMin(B.x[v]), hi = hi.cwiseMax(B.x[v]);
    for (std::size_t a = 0; a < bodies.size(); ++a) {
      if (a == b) continue;
      const double strict = bodies[a].margin + B.margin;
      for (const Vec3& p : bodies[a].x) {
        if (!((p.array() > lo.array()).all() && (p.array() < hi.array()).all())) continue;
        if (!bruteParityOdd(p, B, 0) || !bruteParityOdd(p, B, 1)) continue;
        double depth = inf;
        for (const Triangle& t : B.triangles)
          depth = std::min(depth, testkit::pointTriangleDistance(p, B.x[t[0]], B.x[t[1]], B.x[t[2]]));
        if (depth > strict) {
          ++out.vertices;
          out.max_depth = std::max(out.max_depth, depth);
        }
      }
    }
  }
  return out;
}

/// Closed spheres, tori and boxes pushed into each other (random sizes, turns and margins, some
/// margins zero), and an open patch through them, whose vertices may be inside the others too.
std::vector<TruthBody> overlappingClosedBodies(std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(0, 1);
  std::vector<TruthBody> out;
  const int closed = 3 + int(seed % 3);
  for (int k = 0; k <= closed; ++k) {
    TriMesh m;
    const std::size_t n = 120 + std::size_t(u(rng) * 250);
    if (k == closed)
      m = makePatch(1.6, 1.6, 9, 9);
    else if ((k + int(seed)) % 3 == 0)
      m = makeSphere(0.3 + 0.3 * u(rng), n);
    else if ((k + int(seed)) % 3 == 1)
      m = makeTorus(0.45 + 0.2 * u(rng), 0.12 + 0.12 * u(rng), n);
    else
      m = makeBox(Vec3(0.2 + 0.3 * u(rng), 0.2 + 0.3 * u(rng), 0.2 + 0.3 * u(rng)), n);
    // Every other seed leaves the shapes axis-aligned: rays along their edges and vertices.
    if (seed % 2 == 1) m.rotate(randomVec(rng, -1, 1), 3.0 * u(rng));
    m.translate(randomVec(rng, -0.35, 0.35));
    TruthBody b;
    b.x = b.prev = m.vertices;
    b.triangles = m.triangles;
    b.closed = k != closed;
    b.margin = u(rng) < 0.3 ? 0.0 : 0.05 * u(rng);
    out.push_back(std::move(b));
  }
  return out;
}

TEST(TruthInside, PenetrationEqualsBruteForceOnOverlappingClosedMeshes) {
  TriangleGrid grid;  // reused across the configurations, as the runner reuses it across steps
  std::size_t penetrating = 0, cases_with = 0;
  for (std::uint64_t seed = 1; seed <= 24; ++seed) {
    std::vector<TruthBody> bodies = overlappingClosedBodies(seed);
    // Vertices of the patch exactly on cell boundaries of the first closed body's ray columns
    // (the cell of a point is found by a division: such points may fall either way, and must be
    // counted the same), in line with that body's own vertices, and one with a NaN (never inside).
    TruthBody& patch = bodies.back();  // (references into `bodies`: used before the grazers join)
    const TruthBody& first = bodies.front();
    for (int axis = 0; axis < 2; ++axis) {
      RayColumns columns;
      columns.build(first, axis);
      const int cu = (axis + 1) % 3, cw = (axis + 2) % 3;
      for (std::int64_t i = 0; i <= columns.dims()[0]; i += 3)
        for (std::int64_t j = 0; j <= columns.dims()[1]; j += 3) {
          Vec3 p = Vec3::Zero();
          p[axis] = 0.01 * double(i - j);
          p[cu] = columns.originU() + double(i) * columns.cellSize();
          p[cw] = columns.originW() + double(j) * columns.cellSize();
          patch.x.push_back(p);
        }
    }
    // Rays exactly through vertices (and along edges) of that body: the tie rule at work.
    for (std::size_t v = 0; v < first.x.size(); v += 3) {
      patch.x.push_back(first.x[v] - Vec3(0.0625, 0.0, 0.0));
      patch.x.push_back(first.x[v] - Vec3(0.0, 0.0625, 0.0));
      patch.x.push_back(first.x[v] * 0.5);
    }
    patch.x.push_back(Vec3(0.0, std::nan(""), 0.0));
    patch.prev = patch.x;
    // Tiny open bodies barely into the first one through each face of its box (just behind its
    // extreme vertex that way), so that the box tests must not skip a body pair that just meets.
    if (seed % 2 == 0) bodies.front().margin = 0.0;
    for (int k = 0; k < 3; ++k)
      for (double sign : {-1.0, 1.0}) {
        const TruthBody& front = bodies.front();
        Vec3 extreme = front.x[0];
        for (const Vec3& v : front.x)
          if (sign * v[k] > sign * extreme[k]) extreme = v;
        TruthBody grazer;
        Vec3 out = Vec3::Zero(), side = Vec3::Zero();
        out[k] = sign;
        side[(k + 1) % 3] = 1.0;
        grazer.x = {extreme - 0.005 * out, extreme + 0.5 * out, extreme + 0.5 * out + 0.5 * side};
        grazer.prev = grazer.x;
        grazer.triangles = {{0, 1, 2}};
        bodies.push_back(std::move(grazer));
      }
    const Penetration brute = bruteForcePenetration(bodies);
    const Penetration pen = measurePenetration(bodies, grid);
    EXPECT_EQ(pen.vertices, brute.vertices) << "seed " << seed;
    EXPECT_EQ(pen.max_depth, brute.max_depth) << "seed " << seed;
    penetrating += brute.vertices;
    cases_with += brute.vertices > 0;
  }
  // Deep and shallow insides in most configurations, not a comparison of zeros.
  EXPECT_GT(penetrating, 2000u);
  EXPECT_GT(cases_with, 20u);
}

TEST(TruthInside, RayColumnsCountLikeTheGrid) {
  // The columns measurePenetration casts its rays in against TriangleGrid's own rays, on the
  // tessellated box (rays exactly along its edges and through its vertices) and a turned torus,
  // from points on the columns' cell boundaries, at the mesh's vertices and at random.
  std::vector<TruthBody> bodies(2);
  const TriMesh box = makeBox(Vec3(1, 1, 1), 300);
  TriMesh torus = makeTorus(0.8, 0.3, 500);
  torus.rotate(Vec3(1, 2, 3), 0.7).translate(Vec3(2.5, 0.1, -0.2));
  bodies[0].x = box.vertices;
  bodies[0].triangles = box.triangles;
  bodies[1].x = torus.vertices;
  bodies[1].triangles = torus.triangles;
  for (TruthBody& b : bodies) b.prev = b.x, b.closed = true;
  TriangleGrid grid;
  grid.build(bodies);
  std::mt19937_64 rng(7);
  std::size_t odd = 0, checked = 0;
  for (Index b = 0; b < 2; ++b)
    for (int axis = 0; axis < 3; ++axis) {
      RayColumns columns;
      columns.build(bodies[b], axis);
      ASSERT_GT(columns.dims()[0] * columns.dims()[1], 16);
      const int cu = (axis + 1) % 3, cw = (axis + 2) % 3;
      std::vector<Vec3> points;
      for (std::int64_t i = 0; i <= columns.dims()[0]; ++i)
        for (std::int64_t j = 0; j <= columns.dims()[1]; ++j) {
          Vec3 p = bodies[b].x[std::size_t(i * 31 + j) % bodies[b].x.size()];
          p[cu] = columns.originU() + double(i) * columns.cellSize();
          p[cw] = columns.originW() + double(j) * columns.cellSize();
          points.push_back(p);
        }
      for (const Vec3& v : bodies[b].x) points.push_back(v), points.push_back(0.5 * v + 0.5 * bodies[b].x[0]);
      for (double x : {-0.5, 0.0, 0.5})
        for (double y : {-0.5, 0.0, 0.5})
          for (double z : {-0.5, 0.0, 0.5}) points.push_back(Vec3(x, y, z));
      for (int r = 0; r < 2000; ++r) points.push_back(randomVec(rng, -1.2, 3.6));
      for (const Vec3& p : points) {
        const bool expected = grid.rayParityOdd(p, b, axis);
        ASSERT_EQ(columns.parityOdd(p), expected) << "body " << b << " axis " << axis << " at " << p.transpose();
        EXPECT_EQ(bruteParityOdd(p, bodies[b], axis), expected);
        odd += expected;
        ++checked;
      }
    }
  EXPECT_GT(odd, checked / 10);
}

}  // namespace
}  // namespace psc::demo
