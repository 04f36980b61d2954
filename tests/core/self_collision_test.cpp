// Self-collision in the core (SensorWorld::setSelfCollision): a body's own (vertex, triangle)
// pairs within its self contact radius R = max(2 × margin, self_radius_edges × mean rest edge)
// come out, except those the exclusion rule names (the triangle holds the vertex, or the two were
// within self_rest_exclusion × R in the rest shape). Checked against brute force over every pair
// of the body, and R against its closed form on a grid cloth.
#include "../../src/bounds.h"

#include "psc/error.h"
#include "psc/shapes.h"
#include "psc/world.h"
#include "psc/testkit/reference.h"

#include <gtest/gtest.h>

#include <Eigen/Geometry>

#include <cmath>
#include <random>
#include <set>
#include <string>
#include <tuple>
#include <vector>

namespace {

using namespace psc;

constexpr double kPi = 3.14159265358979323846;

/// A patch in the xy plane (centred on the origin) folded over a cylinder of radius rho around the line
/// x = fold, z = rho: the part beyond the fold lies above the part before it, 2·rho apart.
std::vector<Vec3> folded(const std::vector<Vec3>& flat, double fold, double rho) {
  std::vector<Vec3> out = flat;
  for (Vec3& p : out) {
    const double s = p.x() - fold;
    if (s <= 0.0) continue;
    if (s <= kPi * rho) {
      p = Vec3(fold + rho * std::sin(s / rho), p.y(), rho * (1.0 - std::cos(s / rho)));
    } else {
      p = Vec3(fold - (s - kPi * rho), p.y(), 2.0 * rho);
    }
  }
  return out;
}

struct Reference {
  std::size_t within = 0;    // pairs within the radius, not excluded
  std::size_t excluded = 0;  // pairs within the radius that the rule excludes
  std::set<std::pair<Index, Index>> pairs;
};

Reference bruteForce(const TriMesh& mesh, const std::vector<Vec3>& rest, double radius, double exclusion) {
  Reference r;
  for (Index v = 0; v < mesh.vertices.size(); ++v)
    for (Index t = 0; t < mesh.triangles.size(); ++t) {
      const Triangle& tri = mesh.triangles[t];
      const Vec3& x = mesh.vertices[v];
      if (!(testkit::pointTriangleDistance(x, mesh.vertices[tri[0]], mesh.vertices[tri[1]], mesh.vertices[tri[2]]) <
            radius))
        continue;
      const bool incident = tri[0] == v || tri[1] == v || tri[2] == v;
      if (incident || testkit::pointTriangleDistance(rest[v], rest[tri[0]], rest[tri[1]], rest[tri[2]]) <
                          exclusion * radius) {
        ++r.excluded;
        continue;
      }
      ++r.within;
      r.pairs.insert({v, t});
    }
  return r;
}

/// A body of `mesh` (positions viewed in place) with self-collision on: its positions now are its
/// rest shape.
BodyDesc selfColliding(const TriMesh& mesh, double margin) {
  BodyDesc d;
  d.triangles = mesh.triangles;
  d.positions = PositionView::of(mesh.vertices);
  d.margin = margin;
  d.self_collision = true;
  return d;
}

/// f(v, t, distance now) for every pair of `mesh` that the self exclusion rule leaves in: the
/// triangle does not hold the vertex, and the two were at least `exclusion` apart in `rest`.
template <class F>
void forEachPairBeyondTheRule(const TriMesh& mesh, const std::vector<Vec3>& rest, const std::vector<Vec3>& now,
                              double exclusion, F&& f) {
  for (Index v = 0; v < now.size(); ++v)
    for (Index t = 0; t < mesh.triangles.size(); ++t) {
      const Triangle& tri = mesh.triangles[t];
      if (tri[0] == v || tri[1] == v || tri[2] == v) continue;
      if (testkit::pointTriangleDistance(rest[v], rest[tri[0]], rest[tri[1]], rest[tri[2]]) < exclusion) continue;
      f(v, t, testkit::pointTriangleDistance(now[v], now[tri[0]], now[tri[1]], now[tri[2]]));
    }
}

/// The mean edge of makePatch(w, h, nx, ny) in closed form: (nx−1)·ny edges of w/(nx−1) along x,
/// nx·(ny−1) of h/(ny−1) along y and (nx−1)·(ny−1) diagonals.
double patchMeanEdge(double w, double h, double nx, double ny) {
  const double dx = w / (nx - 1), dy = h / (ny - 1);
  const double ex = (nx - 1) * ny, ey = nx * (ny - 1), ed = (nx - 1) * (ny - 1);
  return (ex * dx + ey * dy + ed * std::hypot(dx, dy)) / (ex + ey + ed);
}

std::set<std::pair<Index, Index>> selfCandidates(const StepResult& res, BodyId id, std::size_t& duplicates) {
  std::set<std::pair<Index, Index>> out;
  duplicates = 0;
  for (const CandidatePair& c : res.candidates)
    if (c.vertex_body == id && c.triangle_body == id && !out.insert({c.vertex, c.triangle}).second) ++duplicates;
  return out;
}

TEST(SelfCollision, FlatClothHasNoSelfCandidatesFoldedClothHasEveryPairOfItsLayers) {
  TriMesh cloth = makePatch(2.0, 1.0, 41, 21);
  const std::vector<Vec3> rest = cloth.vertices;
  const double margin = 0.02;
  BodyDesc d;
  d.triangles = cloth.triangles;
  d.positions = PositionView::of(cloth.vertices);
  d.margin = margin;
  d.self_collision = true;
  d.name = "cloth";
  SensorWorld w;
  const BodyId id = w.addBody(d);
  EXPECT_TRUE(w.selfCollision(id));

  // Lying flat: neighbours are within the radius, but all of them are excluded; the rest-shape
  // bound sees the unmoved cloth and rules it out whole, and without it the rule takes them out.
  const StepResult& flat = w.step();
  std::size_t dup = 0;
  EXPECT_TRUE(selfCandidates(flat, id, dup).empty());
  EXPECT_EQ(flat.stats.self_candidate_pairs, 0u);
  EXPECT_EQ(flat.stats.self_excluded_pairs, 0u);
  EXPECT_EQ(flat.stats.candidate_probes, 0u) << "the bound leaves no box test to make";
  EXPECT_EQ(flat.stats.self_region_pairs_unbent, flat.stats.self_region_pairs);
  {
    SensorSettings boxes_only;
    boxes_only.self_rest_bound = false;
    SensorWorld w0(boxes_only);
    const BodyId id0 = w0.addBody(d);
    const StepResult& flat0 = w0.step();
    EXPECT_TRUE(selfCandidates(flat0, id0, dup).empty());
    EXPECT_GT(flat0.stats.candidate_probes, 0u) << "the flat cloth's neighbours are within reach";
  }

  // Folded in two, the layers 0.03 apart (inside R = 1.25 × the mean edge 0.0567 > 2 × margin):
  // every pair the brute force finds between the layers is a candidate, exactly once, and nothing
  // excluded comes out.
  const double radius = w.settings().self_radius_edges * patchMeanEdge(2.0, 1.0, 41, 21);
  EXPECT_NEAR(w.selfRadius(id), radius, 1e-12);
  cloth.vertices = folded(rest, 0.0, 0.015);
  w.setPositions(id, PositionView::of(cloth.vertices));
  const StepResult& fold = w.step();
  const Reference ref = bruteForce(cloth, rest, radius, w.settings().self_rest_exclusion);
  const std::set<std::pair<Index, Index>> got = selfCandidates(fold, id, dup);
  EXPECT_EQ(dup, 0u);
  EXPECT_GT(ref.within, 500u) << "the layers must touch";
  std::size_t missed = 0;
  for (const auto& p : ref.pairs) missed += got.count(p) == 0;
  EXPECT_EQ(missed, 0u) << "of " << ref.within;
  for (const auto& [v, t] : got) {
    const Triangle& tri = cloth.triangles[t];
    ASSERT_FALSE(tri[0] == v || tri[1] == v || tri[2] == v) << "vertex " << v << " in its own triangle " << t;
    ASSERT_GE(testkit::pointTriangleDistance(rest[v], rest[tri[0]], rest[tri[1]], rest[tri[2]]),
              w.settings().self_rest_exclusion * radius * (1.0 - 1e-9))
        << "excluded pair " << v << ", " << t;
  }
  EXPECT_EQ(fold.stats.self_candidate_pairs, got.size());

  // Off again: no self pairs.
  w.setSelfCollision(id, false);
  EXPECT_FALSE(w.selfCollision(id));
  EXPECT_TRUE(selfCandidates(w.step(), id, dup).empty());
}

TEST(SelfCollision, ABodyMeetsItselfByItsMotionAgainstItselfNotByItsSpeed) {
  // A cloth folded with its layers 1.6 R apart (beyond the self radius R). Moved fast as a whole
  // this step, Bullet's radius R + 2·|d| would take the layers for contacts; the self motion term
  // (psc::selfMotion: |d| against the body's mean displacement) gives none. With its top layer
  // also moving down by R relative to the rest, both layers reach across, and the candidates are
  // exactly the brute force's pairs within R + 2·selfMotion.
  TriMesh cloth = makePatch(2.0, 1.0, 41, 21);
  const std::vector<Vec3> rest = cloth.vertices;
  SensorWorld w;
  const BodyId id = w.addBody(selfColliding(cloth, 0.01));
  w.step();
  const double radius = w.selfRadius(id), mf = w.settings().motion_factor;
  const std::vector<Vec3> now = folded(rest, 0.0, 0.8 * radius);
  const Vec3 fast(0.5, 0.2, -0.3);
  for (const bool top_moves : {false, true}) {
    std::vector<Vec3> before(now.size());
    for (std::size_t v = 0; v < now.size(); ++v) {
      const bool top = now[v].z() > 1.5 * radius;
      before[v] = now[v] - fast - (top_moves && top ? Vec3(0, 0, -radius) : Vec3::Zero());
    }
    w.setPositions(id, PositionView::of(now), PositionView::of(before));
    std::size_t dup = 0;
    const std::set<std::pair<Index, Index>> got = selfCandidates(w.step(), id, dup);
    EXPECT_EQ(dup, 0u);
    Vec3 mean = Vec3::Zero();
    for (std::size_t v = 0; v < now.size(); ++v) mean += now[v] - before[v];
    mean /= double(now.size());
    std::set<std::pair<Index, Index>> expected;
    std::size_t bullet_would = 0;
    forEachPairBeyondTheRule(cloth, rest, now, w.settings().self_rest_exclusion * radius,
                             [&](Index v, Index t, double dist) {
      const Vec3 disp = now[v] - before[v];
      const double reach = radius + mf * selfMotion(disp, mean);
      bullet_would += dist < radius + mf * disp.norm();
      if (dist < reach * (1.0 - 1e-6)) expected.insert({v, t});
      // Nothing beyond the self rule's radius, not even by a rounding slack (the exact stage
      // makes a contact of every self candidate: Bullet's radius R + 2·|d| is wider).
      if (got.count({v, t})) {
        EXPECT_LT(dist, reach * (1.0 + 1e-12)) << v << ", " << t;
      }
    });
    EXPECT_GT(bullet_would, 1000u) << "the speed alone would make the layers meet";
    std::size_t missed = 0;
    for (const auto& p : expected) missed += got.count(p) == 0;
    EXPECT_EQ(missed, 0u) << "of " << expected.size();
    if (top_moves) {
      EXPECT_GT(expected.size(), 100u) << "the top layer coming down meets the bottom one";
    } else {
      EXPECT_TRUE(got.empty()) << got.size() << " pairs of a body moving as a whole";
    }
  }
}

TEST(SelfCollision, TheMeanMotionLeavesOutTheVerticesOnNoTriangle) {
  // psc::selfMotion's mean is over the vertices on triangles. A volumetric body's inner nodes (here
  // 94 vertices on no triangle) have chunks and are candidate vertices, but the mean leaves them
  // out: when they move with a vertex that comes down onto a triangle of its own body, the pair is
  // a candidate at the reach the rule gives (the brute force's pairs, exactly), not at the smaller
  // one an all-vertex mean would give (found by a review: the refit's pass summed every vertex).
  TriMesh body;
  body.vertices = {{-1, -1, 0}, {3, -1, 0}, {-1, 3, 0}, {0, 0, 0.3}, {0.5, 0, 0.3}, {0, 0.5, 0.3}};
  body.triangles = {{0, 1, 2}, {3, 4, 5}};
  for (int i = 0; i < 94; ++i) body.vertices.push_back(Vec3(10.0 + 0.1 * i, 10.0, 0.0));
  const std::vector<Vec3> rest = body.vertices;
  SensorSettings settings;
  settings.self_radius_edges = 0.01;  // R = 2 × margin = 0.1, E = 0.2
  for (const bool rest_bound : {true, false}) {
    settings.self_rest_bound = rest_bound;
    SensorWorld w(settings);
    const BodyId id = w.addBody(selfColliding(body, 0.05));
    w.step();
    const double radius = w.selfRadius(id), mf = w.settings().motion_factor;
    ASSERT_DOUBLE_EQ(radius, 0.1);
    // The vertex above the lower triangle and every vertex on no triangle come down by 0.15.
    std::vector<Vec3> now = rest;
    const Vec3 down(0.0, 0.0, -0.15);
    now[3] += down;
    for (std::size_t v = 6; v < now.size(); ++v) now[v] += down;
    w.setPositions(id, PositionView::of(now), PositionView::of(rest));
    std::size_t dup = 0;
    const std::set<std::pair<Index, Index>> got = selfCandidates(w.step(), id, dup);
    EXPECT_EQ(dup, 0u);
    Vec3 mean = Vec3::Zero();
    for (Index v = 0; v < 6; ++v) mean += now[v] - rest[v];
    mean /= 6.0;
    std::set<std::pair<Index, Index>> expected;
    forEachPairBeyondTheRule(body, rest, now, w.settings().self_rest_exclusion * radius,
                             [&](Index v, Index t, double dist) {
      if (dist < radius + mf * selfMotion(now[v] - rest[v], mean)) expected.insert({v, t});
    });
    EXPECT_EQ(expected, (std::set<std::pair<Index, Index>>{{3, 0}})) << "0.15 from the triangle, reach 0.35";
    EXPECT_EQ(got, expected) << "rest-shape bound " << rest_bound;
  }
}

/// The distance from p to the plane of (a, b, c) in long double, from differences (p projects
/// inside the triangle in the test below, so it is the point–triangle distance).
long double planeDistance(const Vec3& p, const Vec3& a, const Vec3& b, const Vec3& c) {
  long double ab[3], ac[3], ap[3];
  for (int i = 0; i < 3; ++i) {
    ab[i] = static_cast<long double>(b[i]) - a[i];
    ac[i] = static_cast<long double>(c[i]) - a[i];
    ap[i] = static_cast<long double>(p[i]) - a[i];
  }
  const long double n[3] = {ab[1] * ac[2] - ab[2] * ac[1], ab[2] * ac[0] - ab[0] * ac[2], ab[0] * ac[1] - ab[1] * ac[0]};
  return std::fabs((n[0] * ap[0] + n[1] * ap[1] + n[2] * ap[2]) / std::sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]));
}

TEST(SelfCollision, FarFromTheOriginNoPairAtTheEdgesOfTheRuleIsLost) {
  // A vertex just inside R of a triangle of its own body now, just beyond E of it at rest: a
  // candidate, however far from the origin the body lies. Two roundings at the coordinates'
  // magnitude dropped such pairs (found by a review): the triangles' rest centroids of the
  // exclusion pre-filter, summed at full magnitude (now taken from the chunk's first vertex), and
  // y = x − R·rest of the rest-shape bound, made at the magnitude of x and rest while the room it
  // is compared with is small (now RestFit::rounding more room).
  const double margin = 1.0 / 128, radius = 2.0 * margin, exclusion = 2.0 * radius;  // R = 2^-6
  const std::vector<Triangle> triangles = {{0, 1, 2}, {3, 4, 5}, {3, 5, 6}, {3, 6, 4}};
  std::mt19937_64 rng(7);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  const auto randomTurn = [&]() {
    Eigen::Quaterniond q(u(rng), u(rng), u(rng), u(rng));
    q.normalize();
    return q;
  };
  for (const bool rest_bound : {true, false}) {
    std::size_t promised = 0, lost = 0;
    for (int trial = 0; trial < 400; ++trial) {
      // A triangle and, above its middle, a vertex with a fan of three triangles: just beyond E at
      // rest, and just inside R now; each placed by its own rotation and a translation of about 1e6.
      const double above = exclusion * (1.0 + 1e-12);
      std::vector<Vec3> shape = {{0.1, 0, 0},  {-0.05, 0.0866, 0},   {-0.05, -0.0866, 0}, {0, 0, above},
                                 {0.02, 0, above}, {-0.01, 0.0173, above}, {-0.01, -0.0173, above}};
      const Eigen::Quaterniond q_rest = randomTurn(), q_now = randomTurn();
      const Vec3 k_rest(1e6 * (1 + 0.1 * u(rng)), 1e6 * u(rng), 1e6 * u(rng));
      const Vec3 k_now(1e6 * u(rng), 1e6 * (1 + 0.1 * u(rng)), 1e6 * u(rng));
      std::vector<Vec3> rest(shape.size()), now(shape.size());
      for (std::size_t i = 0; i < shape.size(); ++i) rest[i] = q_rest * shape[i] + k_rest;
      shape[3].z() = radius * (1.0 - 1e-12);
      for (std::size_t i = 0; i < shape.size(); ++i) now[i] = q_now * shape[i] + k_now;
      // Promised after the inputs' own rounding: inside R now, beyond E at rest.
      if (!(planeDistance(now[3], now[0], now[1], now[2]) < radius) ||
          !(planeDistance(rest[3], rest[0], rest[1], rest[2]) >= exclusion))
        continue;
      ++promised;
      SensorSettings settings;
      settings.self_radius_edges = 0.01;
      settings.chunk_vertices = 4;
      settings.self_rest_bound = rest_bound;
      SensorWorld w(settings);
      std::vector<Vec3> positions = rest;
      BodyDesc d;
      d.triangles = triangles;
      d.positions = PositionView::of(positions);
      d.margin = margin;
      d.self_collision = true;
      const BodyId id = w.addBody(d);
      w.step();
      positions = now;
      w.setPositions(id, PositionView::of(positions));
      std::size_t dup = 0;
      lost += selfCandidates(w.step(), id, dup).count({3, 0}) == 0;
    }
    EXPECT_GT(promised, 50u);
    EXPECT_EQ(lost, 0u) << "of " << promised << " promised pairs, rest-shape bound " << rest_bound;
  }
  // Translated far along z only (the rotation stays exactly the identity), the vertex pushed to
  // just inside R: the rest-shape bound's room alone decided.
  const double translation = std::ldexp(1.0, 19) + 0.5, grid = std::ldexp(1.0, -32);
  const double gap = std::floor(0.01 / grid) * grid, r = gap + 2e-11;
  const double height = 2.0 * r + 1e-12, upper = std::ceil(4.0 * r / grid) * grid;
  std::vector<Vec3> positions = {{0.13, 0.02, 0},          {-0.02, 0.1066, 0},      {-0.02, -0.0666, 0}, {0, 0, height},
                                 {-0.01, -0.02, upper}, {-0.04, -0.0027, upper}, {-0.04, -0.0373, upper}};
  SensorSettings settings;
  settings.self_radius_edges = 0.0;
  SensorWorld w(settings);
  BodyDesc d;
  d.triangles = triangles;
  d.positions = PositionView::of(positions);
  d.margin = r / 2;
  d.self_collision = true;
  const BodyId id = w.addBody(d);
  w.step();
  for (Vec3& p : positions) p.z() += translation;
  positions[3] = Vec3(0, 0, translation + gap);
  w.setPositions(id, PositionView::of(positions));
  std::size_t dup = 0;
  EXPECT_EQ(selfCandidates(w.step(), id, dup).count({3, 0}), 1u) << gap << " from the triangle, R " << w.selfRadius(id);
}

TEST(SelfCollision, NoSelfCandidateLiesBeyondTheSelfRadiusNotEvenByARoundingSlack) {
  // A cloth folded with its layers R·(1 + 4e-6) apart, at rest this step. A two-body pair keeps a
  // rounding slack (1e-5 of the radius, for Bullet's single-precision test, which then decides);
  // a self pair is decided by the core alone (the exact stage makes a contact of each: Bullet's
  // radius R + 2·|d| is wider), so the slack would put contacts beyond the rule's radius.
  TriMesh cloth = makePatch(2.0, 1.0, 41, 21);
  const std::vector<Vec3> rest = cloth.vertices;
  SensorWorld w;
  const BodyId id = w.addBody(selfColliding(cloth, 0.01));
  w.step();
  const double radius = w.selfRadius(id);
  const double gap = radius * (1.0 + 4e-6);
  // Turned, so that the triangles' boxes do not already keep the layers apart.
  const Eigen::Matrix3d turn =
      (Eigen::AngleAxisd(0.6, Vec3::UnitY()) * Eigen::AngleAxisd(0.3, Vec3::UnitX())).toRotationMatrix();
  std::vector<Vec3> now = folded(rest, 0.0, 0.5 * gap);
  for (Vec3& p : now) p = turn * p;
  w.setPositions(id, PositionView::of(now), PositionView::of(now));
  std::size_t dup = 0;
  const std::set<std::pair<Index, Index>> got = selfCandidates(w.step(), id, dup);
  std::size_t within_slack = 0, within_radius = 0;
  forEachPairBeyondTheRule(cloth, rest, now, w.settings().self_rest_exclusion * radius, [&](Index, Index, double dist) {
    within_radius += dist < radius;
    within_slack += dist < radius * (1.0 + 1e-5);
  });
  EXPECT_EQ(within_radius, 0u);
  EXPECT_GT(within_slack, 500u) << "the layers must lie within a two-body pair's slack";
  EXPECT_TRUE(got.empty()) << got.size() << " self candidates beyond the self radius";
}

TEST(SelfCollision, MeetingPairsLeaveABodysPairsWithItselfAsTheSelfRuleHasThem) {
  // SensorSettings::meeting_pairs is for two bodies: a body's pairs with itself stay the self
  // rule's (within R + 2·selfMotion), whose exact stage would otherwise make contacts of pairs the
  // rule leaves out. A folded cloth whose top layer comes down 0.4 this step, through the bottom
  // one: the same self candidates with and without it.
  TriMesh cloth = makePatch(2.0, 1.0, 41, 21);
  const std::vector<Vec3> rest = cloth.vertices;
  SensorSettings settings;
  settings.meeting_pairs = true;
  SensorWorld meeting(settings), plain;
  const BodyId id = meeting.addBody(selfColliding(cloth, 0.01));
  const BodyId id0 = plain.addBody(selfColliding(cloth, 0.01));
  meeting.step();
  plain.step();
  const double radius = meeting.selfRadius(id);
  const std::vector<Vec3> before = folded(rest, 0.0, 1.5 * radius);
  std::vector<Vec3> now = before;
  for (Vec3& p : now)
    if (p.z() > 2.0 * radius) p.z() -= 0.4;
  meeting.setPositions(id, PositionView::of(now), PositionView::of(before));
  plain.setPositions(id0, PositionView::of(now), PositionView::of(before));
  std::size_t dup = 0;
  const std::set<std::pair<Index, Index>> got = selfCandidates(meeting.step(), id, dup);
  const std::set<std::pair<Index, Index>> got_plain = selfCandidates(plain.step(), id0, dup);
  EXPECT_GT(got.size(), 1000u) << "the layers must meet";
  EXPECT_EQ(got, got_plain);
}

TEST(SelfCollision, TheSelfRadiusIsTwiceTheMarginOrAMultipleOfTheMeanRestEdgeWhicheverIsLarger) {
  TriMesh cloth = makePatch(2.0, 1.0, 41, 21);
  const double base = SensorSettings{}.self_radius_edges * patchMeanEdge(2.0, 1.0, 41, 21);  // 1.25 × 0.0567
  BodyDesc d;
  d.triangles = cloth.triangles;
  d.positions = PositionView::of(cloth.vertices);
  d.margin = 0.02;
  SensorWorld w;
  const BodyId id = w.addBody(d);
  EXPECT_EQ(w.selfRadius(id), 0.0) << "self-collision off";
  w.setSelfCollision(id, true);
  EXPECT_NEAR(w.selfRadius(id), base, 1e-12);
  w.setMargin(id, 0.05);
  EXPECT_EQ(w.selfRadius(id), 0.1) << "2 × margin is larger";
  // The base is the rest shape: stretching the cloth now does not change it...
  for (Vec3& p : cloth.vertices) p *= 3.0;
  w.setMargin(id, 0.02);
  EXPECT_NEAR(w.selfRadius(id), base, 1e-12);
  // ...until self-collision is switched on again, which takes the current shape as rest.
  w.setSelfCollision(id, true);
  EXPECT_NEAR(w.selfRadius(id), 3.0 * base, 1e-12);
  EXPECT_EQ(selfContactRadius(0.02, 0.0567, 0.0), 0.04) << "self_radius_edges = 0: twice the margin";

  SensorSettings plain;
  plain.self_radius_edges = 0.0;
  SensorWorld w0(plain);
  d.self_collision = true;
  EXPECT_EQ(w0.selfRadius(w0.addBody(d)), 0.04);
}

TEST(SelfCollision, ARoundBallCannotTouchItself) {
  TriMesh ball = makeSphere(1.0, 800);
  BodyDesc d;
  d.triangles = ball.triangles;
  d.positions = PositionView::of(ball.vertices);
  d.margin = 0.02;
  d.self_collision = true;
  SensorWorld w;
  const BodyId id = w.addBody(d);
  const StepResult& res = w.step();
  std::size_t dup = 0;
  EXPECT_TRUE(selfCandidates(res, id, dup).empty());
  EXPECT_EQ(res.stats.self_candidate_pairs, 0u);
}

TEST(SelfCollision, TheRestShapeBoundDropsOnlyPairsThatCannotTouch) {
  // A ball moved rigidly (turned, shifted, with a previous position for the motion term), then
  // squashed by more and more until its top and bottom meet: the rest-shape bound must keep every
  // candidate that the boxes alone keep, and rule out the chunk pairs of the shape that has not
  // bent.
  const TriMesh ball = makeSphere(1.0, 1500);
  const Eigen::Matrix3d turn = Eigen::AngleAxisd(0.7, Vec3(1, 2, 3).normalized()).toRotationMatrix();
  const Vec3 shift(0.3, -2.0, 0.5), step(0.01, -0.02, 0.005);
  std::size_t unbent_seen = 0, pairs_seen = 0, vertices_unbent_seen = 0;
  for (double squash : {1.0, 0.8, 0.5, 0.2, 0.1}) {
    std::vector<Vec3> now = ball.vertices, before = ball.vertices;
    for (std::size_t v = 0; v < now.size(); ++v) {
      Vec3 p = ball.vertices[v];
      p.z() *= squash;
      now[v] = turn * p + shift;
      before[v] = now[v] - step * (1.0 + 0.1 * std::sin(double(v)));
    }
    std::set<std::pair<Index, Index>> got[2];
    StepStats stats[2];
    for (int bound = 0; bound < 2; ++bound) {
      SensorSettings s;
      s.self_rest_bound = bound == 1;
      SensorWorld w(s);
      BodyDesc d;
      d.triangles = ball.triangles;
      d.positions = PositionView::of(ball.vertices);
      d.margin = 0.01;
      d.self_collision = true;  // the round ball is the rest shape
      const BodyId id = w.addBody(d);
      w.step();
      w.setPositions(id, PositionView::of(now), PositionView::of(before));
      const StepResult& res = w.step();
      std::size_t dup = 0;
      got[bound] = selfCandidates(res, id, dup);
      EXPECT_EQ(dup, 0u);
      stats[bound] = res.stats;
    }
    EXPECT_EQ(got[1], got[0]) << "squash " << squash;
    EXPECT_EQ(stats[0].self_chunk_pairs_unbent + stats[0].self_region_pairs_unbent + stats[0].self_vertices_unbent, 0u)
        << "off means off";
    if (squash == 1.0) {
      EXPECT_TRUE(got[1].empty()) << "a rigidly moved ball cannot touch itself";
      EXPECT_GT(stats[1].self_region_pairs_unbent + stats[1].self_chunk_pairs_unbent, 0u);
    }
    unbent_seen += stats[1].self_chunk_pairs_unbent + stats[1].self_region_pairs_unbent;
    vertices_unbent_seen += stats[1].self_vertices_unbent;
    pairs_seen += got[1].size();
  }
  EXPECT_GT(pairs_seen, 1000u) << "the flattest balls touch themselves";
  EXPECT_GT(unbent_seen, 0u);
  EXPECT_GT(vertices_unbent_seen, 0u) << "the per-vertex bound (dropUnbentPicks) took part";
}

TEST(SelfCollision, TheRestShapeBoundFollowsASpinningBody) {
  // A ball turning 0.02 rad and moving each step (slow enough that the motion term leaves the
  // exclusion distance room): after the first steps the bound's rotation follows the spin (it
  // predicts the next turn from the last), and the whole ball stays ruled out. Over the 12 steps
  // it turns by more than the fit's tolerance allows a rotation to lag.
  const TriMesh ball = makeSphere(1.0, 1500);
  const Vec3 axis = Vec3(1, -2, 0.5).normalized(), velocity(0.005, 0.0025, -0.0075);
  SensorWorld w;
  const BodyId id = w.addBody(selfColliding(ball, 0.01));
  std::vector<Vec3> now = ball.vertices, before = ball.vertices;
  for (int step = 0; step < 12; ++step) {
    before = now;
    const Eigen::Matrix3d turn = Eigen::AngleAxisd(0.02 * step, axis).toRotationMatrix();
    for (std::size_t v = 0; v < now.size(); ++v) now[v] = turn * ball.vertices[v] + double(step) * velocity;
    w.setPositions(id, PositionView::of(now), PositionView::of(before));
    const StepResult& res = w.step();
    std::size_t dup = 0;
    EXPECT_TRUE(selfCandidates(res, id, dup).empty()) << "step " << step;
    if (step >= 3) {
      EXPECT_GT(res.stats.self_region_pairs, 0u);
      EXPECT_EQ(res.stats.self_region_pairs_unbent, res.stats.self_region_pairs) << "step " << step;
    }
  }
}

TEST(SelfCollision, TwoBodiesAndSelfPairsComeOutTogetherSortedByBodies) {
  TriMesh cloth = makePatch(2.0, 1.0, 41, 21);
  const std::vector<Vec3> rest = cloth.vertices;
  TriMesh ball = makeSphere(0.3, 300).translate(Vec3(-0.6, 0.0, 0.35));
  SensorWorld w;
  BodyDesc dc;
  dc.triangles = cloth.triangles;
  dc.positions = PositionView::of(cloth.vertices);
  dc.margin = 0.02;
  const BodyId c = w.addBody(dc);
  BodyDesc db;
  db.triangles = ball.triangles;
  db.positions = PositionView::of(ball.vertices);
  db.margin = 0.02;
  const BodyId b = w.addBody(db);
  w.step();
  w.setSelfCollision(c, true);  // the flat cloth is the rest shape
  cloth.vertices = folded(rest, 0.0, 0.015);
  w.setPositions(c, PositionView::of(cloth.vertices));
  const StepResult& res = w.step();
  std::size_t self = 0, other = 0;
  for (std::size_t i = 0; i < res.candidates.size(); ++i) {
    const CandidatePair& p = res.candidates[i];
    (p.vertex_body == p.triangle_body ? self : other) += 1;
    EXPECT_NE(p.vertex_body == b && p.triangle_body == b, true) << "the ball has no self-collision";
    if (i > 0) {
      const CandidatePair& q = res.candidates[i - 1];
      EXPECT_LE(std::tie(q.vertex_body, q.triangle_body), std::tie(p.vertex_body, p.triangle_body));
    }
  }
  EXPECT_GT(self, 0u);
  EXPECT_GT(other, 0u) << "the ball rests in the fold";
}

TEST(SelfCollision, NeedsTheDefaultOrBoundsModeAndValidSettings) {
  SensorSettings thesis;
  thesis.flagging = Flagging::Sensors;
  SensorWorld w(thesis);
  TriMesh ball = makeSphere(1.0, 100);
  BodyDesc d;
  d.triangles = ball.triangles;
  d.positions = PositionView::of(ball.vertices);
  d.self_collision = true;
  d.name = "ball";
  try {
    w.addBody(d);
    FAIL() << "self-collision in the thesis's mode must throw";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("self-collision"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("ball"), std::string::npos) << e.what();
  }
  SensorSettings bad;
  bad.self_rest_exclusion = 0.5;
  EXPECT_THROW(SensorWorld{bad}, Error);
  for (double edges : {-0.5, std::nan(""), HUGE_VAL}) {
    SensorSettings wrong;
    wrong.self_radius_edges = edges;
    try {
      SensorWorld world{wrong};
      ADD_FAILURE() << "self_radius_edges = " << edges << " accepted";
    } catch (const Error& e) {
      EXPECT_NE(std::string(e.what()).find("self_radius_edges"), std::string::npos) << e.what();
    }
  }
}

// The self pass's two probe paths, AVX2 (four boxes at a time, where the processor has it) and
// SSE2 (two), give the same self candidates in the same order after the same probes: a cloth
// folding in steps until its layers touch, with the rest-shape bound on and off.
TEST(SelfCollision, Avx2AndSse2GiveTheSameSelfCandidates) {
  if (!detail::avx2ProbesAvailable()) GTEST_SKIP() << "no AVX2 on this processor: only the SSE2 path runs";
  TriMesh cloth = makePatch(2.0, 1.0, 41, 21);
  const std::vector<Vec3> rest = cloth.vertices;
  const auto run = [&](bool avx2, bool rest_bound) {
    detail::allowAvx2Probes(avx2);
    SensorSettings settings;
    settings.self_rest_bound = rest_bound;
    SensorWorld w(settings);
    TriMesh mesh = cloth;
    const BodyId id = w.addBody(selfColliding(mesh, 0.01));
    std::vector<CandidatePair> candidates;
    std::size_t probes = 0;
    for (double rho : {0.3, 0.1, 0.04, 0.02, 0.012}) {
      mesh.vertices = folded(rest, 0.1, rho);
      w.setPositions(id, PositionView::of(mesh.vertices));
      const StepResult& r = w.step();
      candidates.insert(candidates.end(), r.candidates.begin(), r.candidates.end());
      probes += r.stats.candidate_probes;
    }
    detail::allowAvx2Probes(true);
    return std::make_pair(candidates, probes);
  };
  for (bool rest_bound : {true, false}) {
    const auto [wide, wide_probes] = run(true, rest_bound);
    const auto [narrow, narrow_probes] = run(false, rest_bound);
    EXPECT_GT(wide.size(), 500u) << "the layers must touch";
    EXPECT_GT(wide_probes, wide.size());
    EXPECT_EQ(wide_probes, narrow_probes);
    EXPECT_TRUE(wide == narrow) << wide.size() << " against " << narrow.size();
  }
}

}  // namespace
