// The benchmark's crossing and tunnelling counts (demos/crossings.h): the two tests on cases whose
// answer is known, and the grid against brute force on random meshes and on a real scene's bodies.
// Its own executable: ctest names these crossings.<suite>.<test>.
#include "crossings.h"
#include "scenes.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <random>

namespace psc::demo {
namespace {

// --- closed-form cases ---

const Vec3 kA(0, 0, 0), kB(1, 0, 0), kC(0, 1, 0);  // a triangle in the plane z = 0

TEST(Segment, ThroughTheInteriorCrossesOnce) {
  EXPECT_TRUE(segmentCrossesTriangle({0.2, 0.2, -1}, {0.2, 0.2, 1}, kA, kB, kC));
  EXPECT_TRUE(segmentCrossesTriangle({0.2, 0.2, 1}, {0.3, 0.1, -1}, kA, kB, kC));  // either direction, slanted
  EXPECT_TRUE(segmentCrossesTriangle({0.2, 0.2, -1}, {0.2, 0.2, 1}, kA, kC, kB));  // either winding
}

TEST(Segment, MissingOrStoppingShortDoesNotCross) {
  EXPECT_FALSE(segmentCrossesTriangle({2, 2, -1}, {2, 2, 1}, kA, kB, kC));        // beside it
  EXPECT_FALSE(segmentCrossesTriangle({0.2, 0.2, -1}, {0.2, 0.2, -0.1}, kA, kB, kC));  // stops short
  EXPECT_FALSE(segmentCrossesTriangle({0.2, 0.2, 0.5}, {0.2, 0.2, 1}, kA, kB, kC));   // above it
  EXPECT_FALSE(segmentCrossesTriangle({0.2, 0.2, -1}, {0.2, 0.2, 0}, kA, kB, kC));    // ends on it: touching
}

TEST(Segment, DegenerateInputsAreNoCrossing) {
  EXPECT_FALSE(segmentCrossesTriangle({-1, 0.2, 0}, {2, 0.2, 0}, kA, kB, kC));    // coplanar, through it
  EXPECT_FALSE(segmentCrossesTriangle({0.2, 0.2, 0}, {0.2, 0.2, 0}, kA, kB, kC)); // zero length, on it
  EXPECT_FALSE(segmentCrossesTriangle({0.5, 0, -1}, {0.5, 0, 1}, kA, kB, kC));    // through an edge exactly
  EXPECT_FALSE(segmentCrossesTriangle({0, 0, -1}, {0, 0, 1}, kA, kB, kC));        // through a vertex exactly
  EXPECT_FALSE(segmentCrossesTriangle({0.2, 0.2, -1}, {0.2, 0.2, 1}, kA, kB, {2, 0, 0}));  // zero area
  EXPECT_FALSE(segmentCrossesTriangle({0.2, 0.2, -1}, {0.2, 0.2, 1}, kA, kA, kA));         // a point
  const double nan = std::nan("");
  EXPECT_FALSE(segmentCrossesTriangle({nan, 0.2, -1}, {0.2, 0.2, 1}, kA, kB, kC));
}

TEST(Segment, NearASharedEdgeExactlyOneOfTheTwoTrianglesCounts) {
  // Two consistently wound triangles sharing the diagonal (0,0,0)-(1,1,0) of the unit square.
  const Vec3 a(0, 0, 0), b(1, 0, 0), c(1, 1, 0), d(0, 1, 0);
  for (double off : {1e-15, -1e-15, 1e-12, -1e-12, 1e-9, -3e-9}) {
    const Vec3 p(0.3, 0.3 + off, -1), q(0.3 + 0.1 * off, 0.3, 1);
    const int hits = int(segmentCrossesTriangle(p, q, a, b, c)) + int(segmentCrossesTriangle(p, q, a, c, d));
    EXPECT_EQ(hits, 1) << "offset " << off;
  }
}

/// A one-triangle body: the triangle (0, 1, 2).
CrossingMesh oneTriangle() { return crossingMesh({{0, 1, 2}}); }

TEST(Count, TwoTrianglesPassingThroughEachOtherCrossTwice) {
  // Their intersection is a segment with an end on each: one edge of each crosses the other.
  const std::vector<CrossingMesh> meshes = {oneTriangle(), oneTriangle()};
  const BodyPositions x = {{kA, kB, kC}, {{0.2, 0.2, -1}, {0.2, 0.2, 1}, {0.2, 3, 0}}};
  CrossingCounter counter;
  EXPECT_EQ(counter.edgeCrossings(meshes, x), 2u);
  EXPECT_EQ(edgeCrossingsBruteForce(meshes, x), 2u);
  // Apart: nothing.
  BodyPositions apart = x;
  for (Vec3& p : apart[1]) p.x() += 5;
  EXPECT_EQ(counter.edgeCrossings(meshes, apart), 0u);
  // A body's own edges never count against its own triangles.
  const std::vector<CrossingMesh> one = {crossingMesh({{0, 1, 2}, {3, 4, 5}})};
  const BodyPositions both = {{kA, kB, kC, {0.2, 0.2, -1}, {0.2, 0.2, 1}, {0.2, 3, 0}}};
  EXPECT_EQ(counter.edgeCrossings(one, both), 0u);
  // They are self crossings, counted separately.
  EXPECT_EQ(counter.selfEdgeCrossings(one, both), 2u);
  EXPECT_EQ(selfEdgeCrossingsBruteForce(one, both), 2u);
  EXPECT_EQ(counter.selfEdgeCrossings(meshes, x), 0u);
}

TEST(Count, SelfCrossingsLeaveOutEdgesOfTheTriangleAndItsNeighbours) {
  // Triangle 1 shares vertex 0 with triangle 0 and its edges (0, 4) and (0, 3) pass through it at
  // vertex 0 only: an edge with a vertex of the triangle is never a self crossing. Its edge (3, 4)
  // does pass through triangle 0's inside.
  const std::vector<CrossingMesh> one = {crossingMesh({{0, 1, 2}, {0, 3, 4}})};
  const BodyPositions x = {{kA, {2, 0, 0}, {0, 2, 0}, {0.5, 0.5, -1}, {0.5, 0.5, 1}}};
  CrossingCounter counter;
  EXPECT_EQ(counter.selfEdgeCrossings(one, x), 1u);
  EXPECT_EQ(selfEdgeCrossingsBruteForce(one, x), 1u);
  // A flat patch has none.
  std::vector<Vec3> flat;
  std::vector<Triangle> tris;
  for (int i = 0; i <= 4; ++i)
    for (int j = 0; j <= 4; ++j) flat.emplace_back(i, j, 0);
  for (Index i = 0; i < 4; ++i)
    for (Index j = 0; j < 4; ++j) {
      tris.push_back({i * 5 + j, i * 5 + j + 5, i * 5 + j + 6});
      tris.push_back({i * 5 + j, i * 5 + j + 6, i * 5 + j + 1});
    }
  EXPECT_EQ(counter.selfEdgeCrossings({crossingMesh(tris)}, {flat}), 0u);
}

TEST(Tunnel, VertexThroughAStaticTriangleTunnels) {
  EXPECT_TRUE(vertexTunnels({0.2, 0.2, 1}, {0.2, 0.2, -1}, kA, kB, kC, kA, kB, kC));
  EXPECT_TRUE(vertexTunnels({0.2, 0.2, -1}, {0.3, 0.1, 1}, kA, kB, kC, kA, kB, kC));
}

TEST(Tunnel, VertexStoppingShortOrOnItOrBesideItDoesNot) {
  EXPECT_FALSE(vertexTunnels({0.2, 0.2, 1}, {0.2, 0.2, 0.1}, kA, kB, kC, kA, kB, kC));  // stops short
  EXPECT_FALSE(vertexTunnels({0.2, 0.2, 1}, {0.2, 0.2, 0}, kA, kB, kC, kA, kB, kC));    // stops on it
  EXPECT_FALSE(vertexTunnels({0.2, 0.2, 0}, {0.2, 0.2, 1}, kA, kB, kC, kA, kB, kC));    // leaves from it
  EXPECT_FALSE(vertexTunnels({2, 2, 1}, {2, 2, -1}, kA, kB, kC, kA, kB, kC));           // beside it
  EXPECT_FALSE(vertexTunnels({0.2, 0.2, 1}, {0.2, 0.2, 1}, kA, kB, kC, kA, kB, kC));    // still
}

TEST(Tunnel, MovingTriangles) {
  const Vec3 up(0, 0, 2);
  // The triangle sweeps over a still vertex.
  EXPECT_TRUE(vertexTunnels({0.2, 0.2, 1}, {0.2, 0.2, 1}, kA, kB, kC, kA + up, kB + up, kC + up));
  // Vertex and triangle move together: never on the plane.
  EXPECT_FALSE(vertexTunnels({0.2, 0.2, 1}, Vec3(0.2, 0.2, 1) + up, kA, kB, kC, kA + up, kB + up, kC + up));
  // The triangle passes the vertex's path, but to the side of where the vertex is then.
  EXPECT_FALSE(vertexTunnels({0.2, 0.2, 1}, {0.2, 0.2, 1}, kA + Vec3(5, 0, 0), kB + Vec3(5, 0, 0),
                             kC + Vec3(5, 0, 0), kA + Vec3(5, 0, 2), kB + Vec3(5, 0, 2), kC + Vec3(5, 0, 2)));
  // The triangle turns about its edge on the x axis (c moves from (0, 1, 0) to (0, −1, 2)) and
  // sweeps over a still vertex above it: the root is at t = 0.375, the vertex inside.
  EXPECT_TRUE(vertexTunnels({0.2, 0.1, 0.3}, {0.2, 0.1, 0.3}, kA, kB, {0, 1, 0}, kA, kB, {0, -1, 2}));
  // Degenerate: a point-like triangle, and one that is coplanar with the path all along.
  EXPECT_FALSE(vertexTunnels({0, 0, 1}, {0, 0, -1}, kA, kA, kA, kA, kA, kA));
  EXPECT_FALSE(vertexTunnels({-1, 0.2, 0}, {2, 0.2, 0}, kA, kB, kC, kA, kB, kC));
}

TEST(Count, TunnelledVerticesCountEachVertexOnceAndSkipContacts) {
  // Body 1's vertex 0 dives through body 0's triangle; its other vertices stay far away.
  const std::vector<CrossingMesh> meshes = {oneTriangle(), oneTriangle()};
  const BodyPositions before = {{kA, kB, kC}, {{0.2, 0.2, 1}, {5, 5, 1}, {5, 6, 1}}};
  BodyPositions after = before;
  after[1][0] = {0.2, 0.2, -1};
  CrossingCounter counter;
  EXPECT_EQ(counter.tunnelledVertices(meshes, before, after, {}), 1u);
  EXPECT_EQ(tunnelledVerticesBruteForce(meshes, before, after, {}), 1u);
  const std::vector<std::vector<char>> skip = {{0, 0, 0}, {1, 0, 0}};  // it had a contact
  EXPECT_EQ(counter.tunnelledVertices(meshes, before, after, skip), 0u);
  std::size_t passed = 0;  // ... and passed all the same
  EXPECT_EQ(counter.tunnelledVertices(meshes, before, after, skip, &passed), 0u);
  EXPECT_EQ(passed, 1u);
  // Stopping short of the triangle is no tunnelling.
  after[1][0] = {0.2, 0.2, 0.05};
  EXPECT_EQ(counter.tunnelledVertices(meshes, before, after, {}), 0u);
  // Two triangles under the path: still one vertex.
  const std::vector<CrossingMesh> stacked = {crossingMesh({{0, 1, 2}, {3, 4, 5}}), oneTriangle()};
  const Vec3 down(0, 0, -0.5);
  BodyPositions b2 = {{kA, kB, kC, kA + down, kB + down, kC + down}, before[1]};
  BodyPositions a2 = b2;
  a2[1][0] = {0.2, 0.2, -1};
  EXPECT_EQ(counter.tunnelledVertices(stacked, b2, a2, {}), 1u);
}

TEST(Count, NonFinitePositionsAreNotCounted) {
  const std::vector<CrossingMesh> meshes = {oneTriangle(), oneTriangle()};
  const double nan = std::nan("");
  BodyPositions x = {{kA, kB, kC}, {{0.2, 0.2, -1}, {0.2, 0.2, 1}, {nan, 3, 0}}};
  CrossingCounter counter;
  // Edge (0, 1) of body 1 still crosses; nothing that touches the NaN vertex is counted.
  EXPECT_EQ(counter.edgeCrossings(meshes, x), edgeCrossingsBruteForce(meshes, x));
  EXPECT_EQ(counter.edgeCrossings(meshes, x), 1u);
  const BodyPositions inf = {{kA, kB, kC}, {Vec3::Constant(INFINITY), Vec3::Constant(-INFINITY), {0, 0, nan}}};
  EXPECT_EQ(counter.edgeCrossings(meshes, inf), 0u);
  EXPECT_EQ(counter.tunnelledVertices(meshes, x, inf, {}), 0u);
}

TEST(Edges, EachUndirectedEdgeOnce) {
  // Two triangles sharing an edge, one wound the other way, and a degenerate one.
  const std::vector<Edge> e = meshEdges({{0, 1, 2}, {2, 1, 3}, {1, 2, 1}, {4, 4, 4}});
  EXPECT_EQ(e, (std::vector<Edge>{{0, 1}, {0, 2}, {1, 2}, {1, 3}, {2, 3}}));
}

// --- the grid against brute force ---

Vec3 randomVec(std::mt19937_64& rng, double lo, double hi) {
  std::uniform_real_distribution<double> u(lo, hi);
  return {u(rng), u(rng), u(rng)};
}

/// A bumpy n×n grid patch of side 1 (2n² triangles), rotated at random and centred at `center`.
void randomPatch(std::mt19937_64& rng, int n, const Vec3& center, std::vector<Vec3>& x, std::vector<Triangle>& tris) {
  std::normal_distribution<double> g;
  const Eigen::Matrix3d rot = Eigen::Quaterniond(g(rng), g(rng), g(rng), g(rng)).normalized().toRotationMatrix();
  std::uniform_real_distribution<double> bump(-0.05, 0.05);
  for (int i = 0; i <= n; ++i)
    for (int j = 0; j <= n; ++j)
      x.push_back(center + rot * Vec3(double(i) / n - 0.5, double(j) / n - 0.5, bump(rng)));
  const auto id = [n](int i, int j) { return static_cast<Index>(i * (n + 1) + j); };
  for (int i = 0; i < n; ++i)
    for (int j = 0; j < n; ++j) {
      tris.push_back({id(i, j), id(i + 1, j), id(i + 1, j + 1)});
      tris.push_back({id(i, j), id(i + 1, j + 1), id(i, j + 1)});
    }
}

struct RandomBodies {
  std::vector<CrossingMesh> meshes;
  BodyPositions before, after;
  std::vector<std::vector<char>> skip;
};

/// `bodies` bumpy patches within `spread` of each other (they cross when it is small), then moved
/// over one step: each translated by up to `motion` plus a little noise per vertex. About one
/// vertex in ten is marked as having had a contact.
RandomBodies randomBodies(std::uint64_t seed, int bodies, double spread, double motion) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(0, 1);
  RandomBodies r;
  for (int b = 0; b < bodies; ++b) {
    std::vector<Vec3> x;
    std::vector<Triangle> tris;
    randomPatch(rng, 6 + int(seed % 5), randomVec(rng, -spread, spread), x, tris);
    const Vec3 shift = randomVec(rng, -motion, motion);
    std::vector<Vec3> after = x;
    std::vector<char> skip(x.size());
    for (std::size_t v = 0; v < x.size(); ++v) {
      after[v] += shift + randomVec(rng, -0.02, 0.02);
      skip[v] = u(rng) < 0.1;
    }
    r.meshes.push_back(crossingMesh(std::move(tris)));
    r.before.push_back(std::move(x));
    r.after.push_back(std::move(after));
    r.skip.push_back(std::move(skip));
  }
  return r;
}

TEST(Grid, EqualsBruteForceOnRandomMeshes) {
  CrossingCounter counter;  // one counter throughout: its buffers are reused
  std::size_t crossings_seen = 0, tunnelled_seen = 0, empty_cases = 0;
  for (std::uint64_t seed = 1; seed <= 16; ++seed) {
    // Seeds alternate between crossing piles and bodies far apart.
    const double spread = seed % 4 == 0 ? 20.0 : 0.3;
    const RandomBodies r = randomBodies(seed, 2 + int(seed % 3), spread, seed % 2 ? 0.6 : 0.1);
    const std::string what = "seed " + std::to_string(seed);
    for (const BodyPositions* x : {&r.before, &r.after}) {
      const std::size_t brute = edgeCrossingsBruteForce(r.meshes, *x);
      EXPECT_EQ(counter.edgeCrossings(r.meshes, *x), brute) << what;
      crossings_seen += brute;
      empty_cases += brute == 0;
    }
    const std::vector<std::vector<char>> none;
    for (const auto* skip : {&r.skip, &none}) {
      const std::size_t brute = tunnelledVerticesBruteForce(r.meshes, r.before, r.after, *skip);
      EXPECT_EQ(counter.tunnelledVertices(r.meshes, r.before, r.after, *skip), brute) << what;
      std::size_t passed = 0;  // every vertex's passage, whatever it skips
      EXPECT_EQ(counter.tunnelledVertices(r.meshes, r.before, r.after, *skip, &passed), brute) << what;
      EXPECT_EQ(passed, tunnelledVerticesBruteForce(r.meshes, r.before, r.after, none)) << what;
      tunnelled_seen += brute;
    }
  }
  // The comparison must have had something to compare, and the far-apart seeds nothing.
  EXPECT_GT(crossings_seen, 100u);
  EXPECT_GT(tunnelled_seen, 50u);
  EXPECT_GE(empty_cases, 8u);
}

/// The bodies of `r` as one body (their vertices renumbered one after another), at `x`.
std::pair<std::vector<CrossingMesh>, BodyPositions> asOneBody(const RandomBodies& r, const BodyPositions& x) {
  std::vector<Triangle> tris;
  std::vector<Vec3> all;
  for (std::size_t b = 0; b < r.meshes.size(); ++b) {
    const auto offset = static_cast<Index>(all.size());
    for (Triangle t : r.meshes[b].triangles) {
      for (Index& v : t) v += offset;
      tris.push_back(t);
    }
    all.insert(all.end(), x[b].begin(), x[b].end());
  }
  return {{crossingMesh(std::move(tris))}, {std::move(all)}};
}

TEST(Grid, SelfCrossingsEqualBruteForceOnRandomMeshes) {
  CrossingCounter counter;
  std::size_t seen = 0;
  for (std::uint64_t seed = 1; seed <= 12; ++seed) {
    const RandomBodies r = randomBodies(seed, 2 + int(seed % 3), seed % 4 == 0 ? 20.0 : 0.3, 0.1);
    const std::string what = "seed " + std::to_string(seed);
    // Each patch alone, several per call: a bumpy patch may fold through itself.
    EXPECT_EQ(counter.selfEdgeCrossings(r.meshes, r.after), selfEdgeCrossingsBruteForce(r.meshes, r.after)) << what;
    // All patches as one body: their crossings between each other are now self crossings.
    const auto [meshes, x] = asOneBody(r, r.after);
    const std::size_t brute = selfEdgeCrossingsBruteForce(meshes, x);
    EXPECT_EQ(counter.selfEdgeCrossings(meshes, x), brute) << what;
    EXPECT_EQ(brute, edgeCrossingsBruteForce(r.meshes, r.after) + selfEdgeCrossingsBruteForce(r.meshes, r.after))
        << what;
    seen += brute;
  }
  EXPECT_GT(seen, 100u);
}

TEST(Grid, EqualsBruteForceOnTwoSpheresPushedTogether) {
  SceneParams params;
  params.resolution = 300;
  const Scene scene = makeScene("head_on", params);
  ASSERT_EQ(scene.bodies.size(), 2u);
  std::vector<CrossingMesh> meshes;
  BodyPositions before;
  for (const SoftBodySpec& b : scene.bodies) {
    meshes.push_back(crossingMesh(b.mesh.triangles));
    before.push_back(b.mesh.vertices);
  }
  CrossingCounter counter;
  EXPECT_EQ(counter.edgeCrossings(meshes, before), 0u) << "the scene starts apart";
  // Body 1 moves 80% of the way to body 0's centre: the surfaces pass through each other.
  const auto centre = [](const std::vector<Vec3>& x) {
    Vec3 c = Vec3::Zero();
    for (const Vec3& p : x) c += p;
    return Vec3(c / double(x.size()));
  };
  const Vec3 shift = 0.8 * (centre(before[0]) - centre(before[1]));
  BodyPositions after = before;
  for (Vec3& p : after[1]) p += shift;
  const std::size_t crossings = counter.edgeCrossings(meshes, after);
  EXPECT_EQ(crossings, edgeCrossingsBruteForce(meshes, after));
  EXPECT_GT(crossings, 10u);
  const std::size_t tunnelled = counter.tunnelledVertices(meshes, before, after, {});
  EXPECT_EQ(tunnelled, tunnelledVerticesBruteForce(meshes, before, after, {}));
  EXPECT_GT(tunnelled, 10u);
}

// --- the item grid: owned edges, near pairs from the topology, the others from the cells ---

/// An n×m grid of quads in the (u, v) parameter square [0, 1]², two triangles each, mapped to 3D
/// by `at`.
template <class At>
void gridSheet(int n, int m, At at, std::vector<Vec3>& x, std::vector<Triangle>& tris) {
  const auto first = static_cast<Index>(x.size());
  for (int i = 0; i <= n; ++i)
    for (int j = 0; j <= m; ++j) x.push_back(at(double(i) / n, double(j) / m));
  const auto id = [&](int i, int j) { return first + static_cast<Index>(i * (m + 1) + j); };
  for (int i = 0; i < n; ++i)
    for (int j = 0; j < m; ++j) {
      tris.push_back({id(i, j), id(i + 1, j), id(i + 1, j + 1)});
      tris.push_back({id(i, j), id(i + 1, j + 1), id(i, j + 1)});
    }
}

TEST(SelfGrid, ASheetPiercedByAStripCrossesAKnownNumberOfTimes) {
  // A square [0, 10]² in z = 0 (two triangles, diagonal x = y) and a strip of k quads in the plane
  // y = 5.3, x in [0.5, 9.5], z in [−1, 1]: each of the strip's k + 1 upright edges and k diagonals
  // passes through the square, and the square's diagonal through the strip (at x = 5.3, off its
  // edges). 2k + 2 crossings, as one body or as two.
  const int k = 6;
  std::vector<Vec3> x = {{0, 0, 0}, {10, 0, 0}, {10, 10, 0}, {0, 10, 0}};
  std::vector<Triangle> tris = {{0, 1, 2}, {0, 2, 3}};
  gridSheet(k, 1, [](double u, double v) { return Vec3(0.5 + 9 * u, 5.3, -1 + 2 * v); }, x, tris);
  CrossingCounter counter;
  const std::vector<CrossingMesh> one = {crossingMesh(tris)};
  EXPECT_EQ(counter.selfEdgeCrossings(one, {x}), std::size_t(2 * k + 2));
  EXPECT_EQ(selfEdgeCrossingsBruteForce(one, {x}), std::size_t(2 * k + 2));
  // The same two as bodies of their own: between bodies now, none within either.
  std::vector<Triangle> strip(tris.begin() + 2, tris.end());
  for (Triangle& t : strip)
    for (Index& v : t) v -= 4;
  const std::vector<CrossingMesh> two = {crossingMesh({{0, 1, 2}, {0, 2, 3}}), crossingMesh(strip)};
  const BodyPositions x2 = {{x.begin(), x.begin() + 4}, {x.begin() + 4, x.end()}};
  EXPECT_EQ(counter.edgeCrossings(two, x2), std::size_t(2 * k + 2));
  EXPECT_EQ(edgeCrossingsBruteForce(two, x2), std::size_t(2 * k + 2));
  EXPECT_EQ(counter.selfEdgeCrossings(two, x2), 0u);
}

TEST(SelfGrid, AStripFoldedBackThroughItselfEqualsBruteForce) {
  // A strip along x folded back at x = 2 over its first half, the returning half twisted about its
  // midline so that it passes through the first half along y = 0.5; near the fold the two halves
  // all but touch.
  for (int n : {8, 20, 41}) {
    std::vector<Vec3> x;
    std::vector<Triangle> tris;
    gridSheet(2 * n, n / 2 + 1,
              [](double u, double v) {
                const double s = 4 * u;
                return s <= 2 ? Vec3(s, v, 0) : Vec3(4 - s, v, (s - 2) * 0.5 * (v - 0.5));
              },
              x, tris);
    const std::vector<CrossingMesh> one = {crossingMesh(tris)};
    CrossingCounter counter;
    const std::size_t brute = selfEdgeCrossingsBruteForce(one, {x});
    EXPECT_EQ(counter.selfEdgeCrossings(one, {x}), brute) << n;
    EXPECT_GT(brute, std::size_t(n)) << n;
  }
}

TEST(SelfGrid, CoordinatesOnALatticeEqualBruteForce) {
  // Vertices snapped to multiples of 1/8: boxes that touch exactly, share faces and sit on cell
  // boundaries, coplanar triangles and edges through vertices and edges, degenerate triangles.
  CrossingCounter counter;
  std::size_t seen = 0;
  for (std::uint64_t seed = 1; seed <= 10; ++seed) {
    RandomBodies r = randomBodies(seed, 3, 0.3, 0.1);
    for (auto& xb : r.after)
      for (Vec3& p : xb) p = (p * 8).array().round().matrix() / 8;
    const auto [meshes, x] = asOneBody(r, r.after);
    const std::size_t brute = selfEdgeCrossingsBruteForce(meshes, x);
    EXPECT_EQ(counter.selfEdgeCrossings(meshes, x), brute) << "seed " << seed;
    EXPECT_EQ(counter.selfEdgeCrossings(r.meshes, r.after), selfEdgeCrossingsBruteForce(r.meshes, r.after))
        << "seed " << seed;
    seen += brute;
  }
  EXPECT_GT(seen, 20u);
}

TEST(SelfGrid, SmallTrianglesFarFromTheOriginEqualBruteForce) {
  // Float boxes round outwards by about 1e-7 of a coordinate: here that is 1e-4 of a triangle.
  CrossingCounter counter;
  for (const double offset : {1e3, -3e4, 1e5}) {
    RandomBodies r = randomBodies(7, 3, 0.3, 0.1);
    for (auto& xb : r.after)
      for (Vec3& p : xb) p = Vec3::Constant(offset) + 0.01 * p;
    const auto [meshes, x] = asOneBody(r, r.after);
    const std::size_t brute = selfEdgeCrossingsBruteForce(meshes, x);
    EXPECT_EQ(counter.selfEdgeCrossings(meshes, x), brute) << offset;
    EXPECT_GT(brute, 0u) << offset;
  }
}

TEST(SelfGrid, NonFiniteVerticesLeaveTheirTrianglesOutButNotTheirOtherEdges) {
  // Triangle (3, 4, 5)'s edge (3, 4) passes through triangle (0, 1, 2); vertex 5 is not finite,
  // so that triangle and its two edges at 5 count for nothing, but edge (3, 4), which it owns,
  // still crosses.
  const std::vector<CrossingMesh> one = {crossingMesh({{0, 1, 2}, {3, 4, 5}})};
  CrossingCounter counter;
  for (const double bad : {std::nan(""), double(INFINITY), -double(INFINITY)}) {
    const BodyPositions x = {{kA, {2, 0, 0}, {0, 2, 0}, {0.3, 0.3, -1}, {0.3, 0.3, 1}, {bad, 0.3, 0}}};
    EXPECT_EQ(counter.selfEdgeCrossings(one, x), 1u) << bad;
    EXPECT_EQ(selfEdgeCrossingsBruteForce(one, x), 1u) << bad;
  }
  // Random folded bodies with some vertices made non-finite: each leaves its triangles out (and
  // hands their other edges to the grid as lone edges). Brute force never counts a NaN, but may
  // count an infinity: it gets NaN for both.
  std::mt19937_64 rng(5);
  std::size_t seen = 0;
  for (std::uint64_t seed = 1; seed <= 8; ++seed) {
    const RandomBodies r = randomBodies(seed, 3, 0.3, 0.1);
    auto [meshes, x] = asOneBody(r, r.after);
    BodyPositions x_nan = x;
    std::uniform_int_distribution<std::size_t> pick(0, x[0].size() - 1);
    for (int i = 0; i < 6; ++i) {
      const std::size_t v = pick(rng);
      const auto k = static_cast<Eigen::Index>(i % 3);
      x[0][v][k] = i % 2 ? std::nan("") : (i % 4 ? INFINITY : -INFINITY);
      x_nan[0][v][k] = std::nan("");
    }
    const std::size_t brute = selfEdgeCrossingsBruteForce(meshes, x_nan);
    EXPECT_EQ(counter.selfEdgeCrossings(meshes, x), brute) << "seed " << seed;
    EXPECT_EQ(counter.selfEdgeCrossings(meshes, x_nan), brute) << "seed " << seed;
    seen += brute;
  }
  EXPECT_GT(seen, 20u);
  // All of a body's vertices but one not finite: nothing, and no trouble.
  BodyPositions all_bad = {std::vector<Vec3>(5, Vec3::Constant(std::nan("")))};
  all_bad[0][0] = kA;
  EXPECT_EQ(counter.selfEdgeCrossings({crossingMesh({{0, 1, 2}, {0, 3, 4}})}, all_bad), 0u);
}

TEST(SelfGrid, EdgesOutsideTheTrianglesAreCountedAsGiven) {
  // CrossingMesh's edges are meshEdges' unless someone writes them: an edge in no triangle, one
  // written larger vertex first and one repeated are each tested as they are, like brute force.
  // Triangle (0, 1, 2) is pierced by the segments 3-4 and 5-6, which are in no triangle.
  CrossingMesh mesh = crossingMesh({{0, 1, 2}, {3, 7, 8}});
  mesh.edges.push_back({5, 6});  // in no triangle
  mesh.edges.push_back({4, 3});  // (3, 4) larger first, in no triangle
  mesh.edges.push_back({0, 1});  // repeated: owned by no triangle, as (0, 1) is taken
  const BodyPositions x = {{kA, {2, 0, 0}, {0, 2, 0}, {0.3, 0.3, -1}, {0.3, 0.3, 1}, {0.4, 0.2, 1}, {0.4, 0.2, -1},
                            {5, 5, 5}, {6, 5, 5}}};
  CrossingCounter counter;
  const std::size_t brute = selfEdgeCrossingsBruteForce({mesh}, x);
  EXPECT_EQ(brute, 2u);
  EXPECT_EQ(counter.selfEdgeCrossings({mesh}, x), brute);
  // The same with a non-finite vertex elsewhere (triangle (3, 7, 8) is left out): they still count.
  BodyPositions bad = x;
  bad[0][8] = Vec3::Constant(std::nan(""));
  EXPECT_EQ(selfEdgeCrossingsBruteForce({mesh}, bad), 2u);
  EXPECT_EQ(counter.selfEdgeCrossings({mesh}, bad), 2u);
}

TEST(SelfGrid, ManyBodiesEqualBruteForce) {
  // Twelve bumpy patches in a pile: each alone (several per call) and between each other, then
  // all as one body.
  const RandomBodies r = randomBodies(11, 12, 0.4, 0.1);
  CrossingCounter counter;
  EXPECT_EQ(counter.selfEdgeCrossings(r.meshes, r.after), selfEdgeCrossingsBruteForce(r.meshes, r.after));
  const std::size_t between = edgeCrossingsBruteForce(r.meshes, r.after);
  EXPECT_EQ(counter.edgeCrossings(r.meshes, r.after), between);
  EXPECT_GT(between, 100u);
  const auto [meshes, x] = asOneBody(r, r.after);
  const std::size_t brute = selfEdgeCrossingsBruteForce(meshes, x);
  EXPECT_EQ(counter.selfEdgeCrossings(meshes, x), brute);
  EXPECT_GT(brute, 100u);
}

TEST(SelfGrid, OneCounterAcrossStepsAndMeshes) {
  // The counter keeps each body's topology while its mesh stays the same: positions that change
  // from call to call, a different set of meshes, a body's mesh changed in place (same sizes) and
  // the first set again must all be counted afresh.
  CrossingCounter counter;
  const RandomBodies a = randomBodies(3, 3, 0.3, 0.4);
  const RandomBodies b = randomBodies(6, 4, 0.3, 0.4);
  const auto check = [&](const std::vector<CrossingMesh>& meshes, const BodyPositions& x, const char* what) {
    EXPECT_EQ(counter.selfEdgeCrossings(meshes, x), selfEdgeCrossingsBruteForce(meshes, x)) << what;
  };
  const auto [one_a, before_a] = asOneBody(a, a.before);
  const auto [one_a_after, after_a] = asOneBody(a, a.after);
  check(one_a, before_a, "a before");
  check(one_a, after_a, "a after");
  check(b.meshes, b.after, "b, four bodies");
  check(a.meshes, a.after, "a, three bodies");
  // Body 0's triangles reordered and turned inside out: the same triangles, counted the same.
  std::vector<CrossingMesh> changed = a.meshes;
  std::rotate(changed[0].triangles.begin(), changed[0].triangles.begin() + 1, changed[0].triangles.end());
  for (Triangle& t : changed[0].triangles) std::swap(t[1], t[2]);
  changed[0] = crossingMesh(changed[0].triangles);
  check(changed, a.after, "a, body 0 reordered");
  // Body 0's mesh replaced in place by one of the same sizes on other vertices (each index moved
  // on by seven): a topology made for the old one would count other pairs.
  const auto vertex_count = static_cast<Index>(a.after[0].size());
  for (Triangle& t : changed[0].triangles)
    for (Index& v : t) v = (v + 7) % vertex_count;
  changed[0] = crossingMesh(changed[0].triangles);
  ASSERT_EQ(changed[0].triangles.size(), a.meshes[0].triangles.size());
  ASSERT_EQ(changed[0].edges.size(), a.meshes[0].edges.size());
  check(changed, a.after, "a, body 0 on other vertices");
  EXPECT_NE(selfEdgeCrossingsBruteForce(changed, a.after), selfEdgeCrossingsBruteForce(a.meshes, a.after));
  // One body made of all of a's, then back to a.
  check(one_a, after_a, "a as one body again");
  check(a.meshes, a.before, "a, three bodies again");
}

}  // namespace
}  // namespace psc::demo
