#include "test_util.h"

#include "psc/error.h"
#include "psc/mesh.h"
#include "psc/shapes.h"

#include <gtest/gtest.h>

#include <Eigen/SVD>

#include <limits>
#include <random>
#include <set>

namespace psc {
namespace {

using test::messageOf;

TEST(Mesh, AdjacencyEqualsBruteForce) {
  const TriMesh m = makeTorus(1.0, 0.3, 400);
  MeshTopology topo(m.triangles, m.vertices.size());
  std::vector<std::set<Index>> ref(m.vertices.size());
  for (const Triangle& t : m.triangles)
    for (int k = 0; k < 3; ++k) {
      ref[t[k]].insert(t[(k + 1) % 3]);
      ref[t[(k + 1) % 3]].insert(t[k]);
    }
  std::size_t edges = 0;
  for (Index v = 0; v < m.vertices.size(); ++v) {
    const auto row = topo.neighbors(v);
    EXPECT_EQ(std::vector<Index>(row.begin(), row.end()), std::vector<Index>(ref[v].begin(), ref[v].end()));
    edges += ref[v].size();
  }
  EXPECT_EQ(topo.edges().size(), edges / 2);
  EXPECT_EQ(topo.componentCount(), 1u);
}

TEST(Mesh, ComponentsAndViewStride) {
  TriMesh a = makeSphere(1.0, 100);
  TriMesh b = makeSphere(1.0, 100);
  b.translate(Vec3(5, 0, 0));
  TriMesh both = a;
  const Index off = static_cast<Index>(a.vertices.size());
  both.vertices.insert(both.vertices.end(), b.vertices.begin(), b.vertices.end());
  for (Triangle t : b.triangles) both.triangles.push_back({t[0] + off, t[1] + off, t[2] + off});
  MeshTopology topo(both.triangles, both.vertices.size());
  EXPECT_EQ(topo.componentCount(), 2u);
  const MeshReport r = validate(topo, PositionView::of(both.vertices));
  EXPECT_EQ(r.components, 2u);
  EXPECT_EQ(r.boundary_edges, 0u);
  EXPECT_EQ(r.inconsistent_winding_edges, 0u);

  // A float view with a stride of 4 floats (btVector3's layout) reads the same points.
  std::vector<float> packed;
  for (const Vec3& p : both.vertices) packed.insert(packed.end(), {float(p.x()), float(p.y()), float(p.z()), 0.f});
  PositionView fv(packed.data(), both.vertices.size(), 4 * sizeof(float));
  for (std::size_t i = 0; i < both.vertices.size(); i += 17)
    EXPECT_NEAR((fv[i] - both.vertices[i]).norm(), 0.0, 1e-6);
}

TEST(Mesh, NormalsPointOutwardOnSphere) {
  const TriMesh m = makeSphere(2.0, 500);
  MeshTopology topo(m.triangles, m.vertices.size());
  const auto n = vertexNormals(topo, PositionView::of(m.vertices));
  for (std::size_t i = 0; i < n.size(); ++i) EXPECT_GT(n[i].dot(m.vertices[i].normalized()), 0.95);
  const EdgeStats es = edgeStats(topo, PositionView::of(m.vertices));
  EXPECT_GT(es.mean, 0.0);
  EXPECT_LE(es.min, es.mean);
  EXPECT_GE(es.max, es.mean);
}

TEST(MeshErrors, IndexOutOfRangeNamesTriangleAndIndex) {
  const std::string msg = messageOf([] { MeshTopology({{0, 1, 2}, {0, 2, 7}}, 4); });
  EXPECT_NE(msg.find("triangle 1"), std::string::npos) << msg;
  EXPECT_NE(msg.find("index 7"), std::string::npos) << msg;
}

TEST(MeshErrors, EmptyMeshes) {
  EXPECT_NE(messageOf([] { MeshTopology({}, 3); }).find("no triangles"), std::string::npos);
  EXPECT_NE(messageOf([] { MeshTopology({{0, 1, 2}}, 0); }).find("no vertices"), std::string::npos);
}

TEST(MeshErrors, NonFiniteCoordinateNamesVertex) {
  TriMesh m = makeSphere(1.0, 50);
  m.vertices[13].y() = std::numeric_limits<double>::quiet_NaN();
  MeshTopology topo(m.triangles, m.vertices.size());
  const std::string msg = messageOf([&] { validate(topo, PositionView::of(m.vertices), "ball"); });
  EXPECT_NE(msg.find("ball"), std::string::npos) << msg;
  EXPECT_NE(msg.find("vertex 13"), std::string::npos) << msg;
  m.vertices[13].y() = std::numeric_limits<double>::infinity();
  EXPECT_NE(messageOf([&] { validate(topo, PositionView::of(m.vertices)); }).find("vertex 13"), std::string::npos);
}

TEST(MeshErrors, ViewSizeMismatch) {
  TriMesh m = makeSphere(1.0, 50);
  MeshTopology topo(m.triangles, m.vertices.size());
  std::vector<Vec3> fewer(m.vertices.begin(), m.vertices.end() - 1);
  const std::string msg = messageOf([&] { validate(topo, PositionView::of(fewer)); });
  EXPECT_NE(msg.find("position view has"), std::string::npos) << msg;
}

TEST(MeshReport, DegenerateDuplicateIsolatedNonManifoldWinding) {
  // Two triangles sharing edge (0,1), a third on the same edge (non-manifold), a zero-area one,
  // a duplicate vertex (5 = 0) and an isolated vertex (6).
  std::vector<Vec3> p{{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0, -1, 0}, {0, 0, 1}, {0, 0, 0}, {9, 9, 9}, {2, 0, 0}};
  std::vector<Triangle> t{{0, 1, 2}, {0, 1, 3}, {1, 0, 4}, {0, 1, 7}};
  MeshTopology topo(t, p.size());
  const MeshReport r = validate(topo, PositionView::of(p));
  EXPECT_EQ(r.non_manifold_edges, 1u);
  EXPECT_EQ(r.degenerate_triangles, 1u);  // 0,1,7 are collinear
  EXPECT_EQ(r.first_degenerate_triangle, 3u);
  EXPECT_EQ(r.duplicate_vertices, 1u);
  EXPECT_EQ(r.isolated_vertices, 2u);  // 5 and 6
  EXPECT_FALSE(r.summary().empty());

  // Flip one triangle of a closed sphere: its three edges are now wound inconsistently.
  TriMesh s = makeSphere(1.0, 60);
  std::swap(s.triangles[0][1], s.triangles[0][2]);
  MeshTopology st(s.triangles, s.vertices.size());
  EXPECT_EQ(validate(st, PositionView::of(s.vertices)).inconsistent_winding_edges, 3u);
}


/// The reference: the rotation factor of A's polar decomposition by SVD, U diag(1, 1, ±1) Vᵀ
/// with the sign that makes it a proper rotation.
Eigen::Matrix3d polarRotationBySvd(const Eigen::Matrix3d& a) {
  const Eigen::JacobiSVD<Eigen::Matrix3d> svd(a, Eigen::ComputeFullU | Eigen::ComputeFullV);
  Eigen::Matrix3d d = Eigen::Matrix3d::Identity();
  if ((svd.matrixU() * svd.matrixV().transpose()).determinant() < 0.0) d(2, 2) = -1.0;
  return svd.matrixU() * d * svd.matrixV().transpose();
}

Eigen::Matrix3d randomRotation(std::mt19937& rng) {
  std::normal_distribution<double> g;
  Eigen::Quaterniond q(g(rng), g(rng), g(rng), g(rng));
  q.normalize();
  return q.toRotationMatrix();
}

TEST(BestRotation, IsThePolarFactorOfRotatedStretches) {
  // A = R S with S symmetric positive definite (a rotated stretch: what a region's fit sees):
  // the answer is R, from the identity and from any start.
  std::mt19937 rng(20261123);
  std::uniform_real_distribution<double> stretch(0.3, 3.0);
  for (int trial = 0; trial < 500; ++trial) {
    const Eigen::Matrix3d rot = randomRotation(rng), axes = randomRotation(rng);
    const Eigen::Matrix3d s =
        axes * Eigen::Vector3d(stretch(rng), stretch(rng), stretch(rng)).asDiagonal() * axes.transpose();
    const Eigen::Matrix3d a = 7.0 * rot * s;
    for (const Eigen::Matrix3d& start : {Eigen::Matrix3d(Eigen::Matrix3d::Identity()), randomRotation(rng)}) {
      const Eigen::Matrix3d got = bestRotation(a, start);
      EXPECT_LT((got - rot).norm(), 1e-6) << "trial " << trial;
      EXPECT_LT((got.transpose() * got - Eigen::Matrix3d::Identity()).norm(), 1e-14);
      EXPECT_NEAR(got.determinant(), 1.0, 1e-14);
    }
  }
}

TEST(BestRotation, ReachesTheSvdOptimumOnGeneralAndFlatMatrices) {
  // Any A, reflections and rank 2 (a flat region) included: tr(Rᵀ A) as large as the SVD's.
  std::mt19937 rng(7);
  std::normal_distribution<double> g;
  for (int trial = 0; trial < 500; ++trial) {
    Eigen::Matrix3d a;
    for (int k = 0; k < 9; ++k) a(k / 3, k % 3) = g(rng);
    if (trial % 3 == 1) a.col(2) = 0.5 * a.col(0) - 2.0 * a.col(1);  // rank 2
    const Eigen::Matrix3d ref = polarRotationBySvd(a);
    const Eigen::Matrix3d got = bestRotation(a, trial % 2 == 0 ? Eigen::Matrix3d(Eigen::Matrix3d::Identity()) : randomRotation(rng));
    EXPECT_NEAR((got.transpose() * a).trace(), (ref.transpose() * a).trace(), 1e-9 * a.norm()) << "trial " << trial;
    EXPECT_NEAR(got.determinant(), 1.0, 1e-14);
  }
}

TEST(BestRotation, GivesTheStartBackForZeroOrNonFiniteInput) {
  const Eigen::Matrix3d start = Eigen::AngleAxisd(0.4, Vec3(0, 0, 1)).toRotationMatrix();
  EXPECT_EQ(bestRotation(Eigen::Matrix3d::Zero(), start), start);
  Eigen::Matrix3d nan = Eigen::Matrix3d::Identity();
  nan(1, 2) = std::numeric_limits<double>::quiet_NaN();
  EXPECT_EQ(bestRotation(nan, start), start);
}

}  // namespace
}  // namespace psc
