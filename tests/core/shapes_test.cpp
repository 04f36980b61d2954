#include "psc/error.h"
#include "psc/shapes.h"

#include "core/test_util.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdlib>

namespace psc {
namespace {

constexpr double kPi = 3.14159265358979323846;

// Every closed shape: a 2-manifold without boundary, one piece, wound consistently, no repeated
// indices, finite coordinates, positive enclosed volume (outward winding).
void expectClosedManifold(const TriMesh& m, const char* what) {
  SCOPED_TRACE(what);
  ASSERT_FALSE(m.triangles.empty());
  for (const Vec3& v : m.vertices) ASSERT_TRUE(v.allFinite());
  for (const Triangle& t : m.triangles) {
    for (Index i : t) ASSERT_LT(i, m.vertices.size());
  }
  const test::EdgeCensus c = test::edgeCensus(m.triangles);
  EXPECT_EQ(c.boundary, 0u);
  EXPECT_EQ(c.non_manifold, 0u);
  EXPECT_EQ(c.same_direction, 0u);
  EXPECT_EQ(c.degenerate_triangles, 0u);
  EXPECT_EQ(test::triangleComponents(m.vertices.size(), m.triangles), 1u);
  // Every vertex is used (no isolated vertices left over by the generators).
  std::vector<bool> used(m.vertices.size(), false);
  for (const Triangle& t : m.triangles) for (Index i : t) used[i] = true;
  EXPECT_EQ(std::count(used.begin(), used.end(), false), 0);
  EXPECT_GT(test::signedVolume(m.vertices, m.triangles), 0.0);
  EXPECT_GT(test::minAreaRatio(m.vertices, m.triangles), 1e-3);
}

std::size_t eulerCharacteristic(const TriMesh& m) {
  const test::EdgeCensus c = test::edgeCensus(m.triangles);
  return m.vertices.size() + m.triangles.size() - c.edges;
}

TEST(Shapes, SphereIsClosedOutwardAndNearRequestedCount) {
  for (std::size_t n : {14u, 20u, 50u, 100u, 500u, 2000u, 10000u}) {
    const TriMesh m = makeSphere(1.5, n);
    expectClosedManifold(m, "sphere");
    EXPECT_EQ(eulerCharacteristic(m), 2u);
    EXPECT_LE(std::abs(double(m.vertices.size()) - double(n)), 0.05 * double(n) + 3.0) << n;
    for (const Vec3& v : m.vertices) EXPECT_NEAR(v.norm(), 1.5, 1e-12);
  }
  const TriMesh smallest = makeSphere(1.0, 14);
  EXPECT_EQ(smallest.vertices.size(), 14u);
  const TriMesh fine = makeSphere(2.0, 5000);
  const double exact = 4.0 / 3.0 * kPi * 8.0;
  EXPECT_NEAR(test::signedVolume(fine.vertices, fine.triangles), exact, 0.01 * exact);
  // Outward per triangle, not only in total.
  for (const Triangle& t : fine.triangles) {
    const Vec3 nrm = (fine.vertices[t[1]] - fine.vertices[t[0]]).cross(fine.vertices[t[2]] - fine.vertices[t[0]]);
    EXPECT_GT(nrm.dot(fine.vertices[t[0]] + fine.vertices[t[1]] + fine.vertices[t[2]]), 0.0);
  }
}

TEST(Shapes, SpherePolesAreSingleVertices) {
  const TriMesh m = makeSphere(1.0, 200);
  int north = 0, south = 0;
  for (const Vec3& v : m.vertices) {
    north += v.z() > 1.0 - 1e-12 ? 1 : 0;
    south += v.z() < -1.0 + 1e-12 ? 1 : 0;
  }
  EXPECT_EQ(north, 1);
  EXPECT_EQ(south, 1);
}

TEST(Shapes, IcosphereCountsAndVolume) {
  const std::size_t expected[] = {12, 42, 162, 642, 2562};
  for (int s = 0; s <= 4; ++s) {
    const TriMesh m = makeIcosphere(1.0, s);
    expectClosedManifold(m, "icosphere");
    EXPECT_EQ(m.vertices.size(), expected[s]);
    EXPECT_EQ(m.triangles.size(), 20u << (2 * s));
    for (const Vec3& v : m.vertices) EXPECT_NEAR(v.norm(), 1.0, 1e-12);
  }
  const TriMesh m = makeIcosphere(3.0, 4);
  const double exact = 4.0 / 3.0 * kPi * 27.0;
  EXPECT_NEAR(test::signedVolume(m.vertices, m.triangles), exact, 0.01 * exact);
}

TEST(Shapes, TorusIsClosedGenusOneWithAnalyticVolume) {
  for (std::size_t n : {9u, 40u, 300u, 1000u, 4000u}) {
    const TriMesh m = makeTorus(2.0, 0.5, n);
    expectClosedManifold(m, "torus");
    EXPECT_EQ(eulerCharacteristic(m), 0u);
    EXPECT_LE(std::abs(double(m.vertices.size()) - double(n)), 0.05 * double(n) + 3.0) << n;
  }
  const TriMesh m = makeTorus(2.0, 0.5, 6000);
  const double exact = 2.0 * kPi * kPi * 2.0 * 0.25;
  EXPECT_NEAR(test::signedVolume(m.vertices, m.triangles), exact, 0.01 * exact);
}

TEST(Shapes, BoxIsClosedExactVolumeAndDeduplicatedEdges) {
  const Vec3 h(1.0, 0.5, 2.0);
  for (std::size_t n : {8u, 26u, 100u, 600u, 3000u}) {
    const TriMesh m = makeBox(h, n);
    expectClosedManifold(m, "box");
    EXPECT_EQ(eulerCharacteristic(m), 2u);
    EXPECT_NEAR(test::signedVolume(m.vertices, m.triangles), 8.0 * h.prod(), 1e-9);
    if (n >= 100) {
      EXPECT_LE(std::abs(double(m.vertices.size()) - double(n)), 0.25 * double(n)) << n;
    }
    for (const Vec3& v : m.vertices) {
      EXPECT_TRUE((v.cwiseAbs() - h).cwiseAbs().minCoeff() < 1e-12);  // on the surface
    }
  }
  EXPECT_EQ(makeBox(h, 8).vertices.size(), 8u);
}

TEST(Shapes, UShapeIsClosedConcaveAndOpensAlongY) {
  const double w = 2.0, arm = 1.5, r = 0.3;
  for (std::size_t n : {32u, 200u, 1000u, 3000u}) {
    const TriMesh m = makeUShape(w, arm, r, n);
    expectClosedManifold(m, "U");
    EXPECT_EQ(eulerCharacteristic(m), 2u);
    EXPECT_LE(std::abs(double(m.vertices.size()) - double(n)), 0.15 * double(n) + 10.0) << n;
  }
  const TriMesh m = makeUShape(w, arm, r, 4000);
  // Tube volume ≈ cross-section × centreline length (exact for a straight tube, and for the bend by
  // Pappus), minus the polygon's shortfall from the circle.
  const double exact = kPi * r * r * (2.0 * arm + kPi * 0.5 * w);
  EXPECT_NEAR(test::signedVolume(m.vertices, m.triangles), exact, 0.02 * exact);
  // Concave: the midpoint between the arms' tips lies outside the tube, inside the hull.
  Vec3 lo = m.vertices[0], hi = m.vertices[0];
  for (const Vec3& v : m.vertices) { lo = lo.cwiseMin(v); hi = hi.cwiseMax(v); }
  EXPECT_NEAR(hi.y(), arm, 1e-9);
  EXPECT_NEAR(lo.y(), -0.5 * w - r, 1e-2);
  EXPECT_NEAR(hi.x(), 0.5 * w + r, 1e-2);
}

TEST(Shapes, ForkIsOneClosedSurface) {
  for (std::size_t n : {40u, 300u, 1000u, 4000u}) {
    const TriMesh m = makeFork(4.0, 0.2, n);
    expectClosedManifold(m, "fork");
    EXPECT_EQ(eulerCharacteristic(m), 2u);
    EXPECT_LE(std::abs(double(m.vertices.size()) - double(n)), 0.2 * double(n) + 20.0) << n;
  }
  const TriMesh m = makeFork(4.0, 0.2, 3000);
  // A handle of length 2 and two prongs of length 2, radius 0.2, plus the flare: between the
  // volume of three plain tubes and that plus a generous allowance for the widened junction.
  const double tubes = kPi * 0.04 * 2.0 * 3.0;
  const double vol = test::signedVolume(m.vertices, m.triangles);
  EXPECT_GT(vol, 0.9 * tubes);
  EXPECT_LT(vol, 1.6 * tubes);
  // Two prongs: near the far end the vertices split into two groups on either side of x = 0, with
  // a gap between them.
  double min_abs_x = 1e9;
  for (const Vec3& v : m.vertices) {
    if (v.y() > 1.5) min_abs_x = std::min(min_abs_x, std::abs(v.x()));
  }
  EXPECT_GT(min_abs_x, 0.15);
}

TEST(Shapes, ConcaveShapesDoNotCrossThemselves) {
  // The checker itself finds crossings: two overlapping spheres in one mesh.
  TriMesh two = makeSphere(1.0, 200);
  TriMesh other = makeSphere(1.0, 200).translate(Vec3(1.0, 0.1, 0.05));
  for (Triangle t : other.triangles) {
    for (Index& i : t) i += static_cast<Index>(two.vertices.size());
    two.triangles.push_back(t);
  }
  two.vertices.insert(two.vertices.end(), other.vertices.begin(), other.vertices.end());
  EXPECT_GT(test::selfIntersections(two.vertices, two.triangles), 10u);
  for (std::size_t n : {60u, 600u}) {
    const TriMesh fork = makeFork(4.0, 0.2, n);
    EXPECT_EQ(test::selfIntersections(fork.vertices, fork.triangles), 0u) << "fork " << n;
    const TriMesh u = makeUShape(1.0, 1.0, 0.45, n);  // tight bend: 0.45 of a 0.5 bend radius
    EXPECT_EQ(test::selfIntersections(u.vertices, u.triangles), 0u) << "U " << n;
    const TriMesh torus = makeTorus(1.0, 0.9, n);
    EXPECT_EQ(test::selfIntersections(torus.vertices, torus.triangles), 0u) << "torus " << n;
  }
}

TEST(Shapes, PatchIsOpenGridFacingUp) {
  const TriMesh m = makePatch(2.0, 1.0, 5, 3);
  EXPECT_EQ(m.vertices.size(), 15u);
  EXPECT_EQ(m.triangles.size(), 2u * 4u * 2u);
  const test::EdgeCensus c = test::edgeCensus(m.triangles);
  EXPECT_EQ(c.boundary, 2u * (4u + 2u));
  EXPECT_EQ(c.non_manifold, 0u);
  EXPECT_EQ(c.same_direction, 0u);
  for (const Triangle& t : m.triangles) {
    const Vec3 nrm = (m.vertices[t[1]] - m.vertices[t[0]]).cross(m.vertices[t[2]] - m.vertices[t[0]]);
    EXPECT_GT(nrm.z(), 0.0);
  }
  Vec3 sum = Vec3::Zero();
  for (const Vec3& v : m.vertices) { sum += v; EXPECT_EQ(v.z(), 0.0); }
  EXPECT_LT(sum.norm(), 1e-12);
  EXPECT_DOUBLE_EQ(m.vertices.front().x(), -1.0);
  EXPECT_DOUBLE_EQ(m.vertices.back().y(), 0.5);
}

TEST(Shapes, TransformsKeepWindingAndCompose) {
  TriMesh m = makeTorus(1.0, 0.25, 400);
  const double vol = test::signedVolume(m.vertices, m.triangles);
  m.rotate(Vec3(1, 1, 0), 0.7).scale(2.0).translate(Vec3(3, -1, 2));
  EXPECT_NEAR(test::signedVolume(m.vertices, m.triangles), 8.0 * vol, 1e-9 * vol);
  TriMesh p = makePatch(1, 1, 2, 2);
  p.rotate(Vec3(0, 0, 5), kPi / 2);  // axis need not be unit
  EXPECT_NEAR(p.vertices[1].x(), 0.5, 1e-12);   // (0.5, −0.5) → (0.5, 0.5)
  EXPECT_NEAR(p.vertices[1].y(), 0.5, 1e-12);
  EXPECT_THROW(p.rotate(Vec3::Zero(), 1.0), Error);
  EXPECT_THROW(p.scale(0.0), Error);
  EXPECT_THROW(p.scale(-1.0), Error);
}

TEST(Shapes, Deterministic) {
  const TriMesh a = makeFork(3.0, 0.2, 800), b = makeFork(3.0, 0.2, 800);
  ASSERT_EQ(a.vertices.size(), b.vertices.size());
  ASSERT_EQ(a.triangles, b.triangles);
  for (std::size_t i = 0; i < a.vertices.size(); ++i) EXPECT_EQ(a.vertices[i], b.vertices[i]);
}

TEST(Shapes, RejectBadArguments) {
  auto expectInvalid = [](auto&& f) {
    try {
      f();
      ADD_FAILURE() << "no exception";
    } catch (const Error& e) {
      EXPECT_EQ(e.code(), ErrorCode::InvalidArgument);
      EXPECT_FALSE(std::string(e.what()).empty());
    }
  };
  expectInvalid([] { makeSphere(0.0, 100); });
  expectInvalid([] { makeSphere(1.0, 13); });
  expectInvalid([] { makeSphere(std::nan(""), 100); });
  expectInvalid([] { makeIcosphere(-1.0, 2); });
  expectInvalid([] { makeIcosphere(1.0, -1); });
  expectInvalid([] { makeTorus(1.0, 0.0, 100); });
  expectInvalid([] { makeTorus(1.0, 1.0, 100); });
  expectInvalid([] { makeTorus(1.0, 0.2, 8); });
  expectInvalid([] { makeBox(Vec3(1, 0, 1), 100); });
  expectInvalid([] { makeBox(Vec3(1, 1, 1), 7); });
  expectInvalid([] { makeUShape(0.5, 1.0, 0.3, 500); });
  expectInvalid([] { makeUShape(2.0, -1.0, 0.3, 500); });
  expectInvalid([] { makeUShape(2.0, 1.0, 0.3, 10); });
  expectInvalid([] { makeFork(0.5, 0.2, 500); });
  expectInvalid([] { makeFork(3.0, 0.0, 500); });
  expectInvalid([] { makePatch(1.0, 1.0, 1, 5); });
  expectInvalid([] { makePatch(0.0, 1.0, 5, 5); });
}

}  // namespace
}  // namespace psc
