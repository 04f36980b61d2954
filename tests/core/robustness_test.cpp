// Bad input and hard conditions (issue 5). Every rejected input must come back as psc::Error whose
// message names the problem; every accepted oddity must be reported in MeshReport and still step.
// Hard conditions are checked against brute force: in the default flagging mode every
// vertex-triangle pair within margin_A + margin_B + motion_factor·|x − x_prev| must be a candidate.

#include "psc/error.h"
#include "psc/partition.h"
#include "psc/shapes.h"
#include "psc/testkit/reference.h"
#include "psc/world.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <cstring>
#include <functional>
#include <initializer_list>
#include <initializer_list>
#include <limits>
#include <random>
#include <set>
#include <string>
#include <thread>
#include <tuple>
#include <vector>

namespace psc {
namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
constexpr double kInf = std::numeric_limits<double>::infinity();

// The message of the psc::Error thrown by f, or a marker when it throws none.
std::string errorOf(const std::function<void()>& f, ErrorCode* code = nullptr) {
  try {
    f();
  } catch (const Error& e) {
    if (code) *code = e.code();
    return e.what();
  }
  return "<no error>";
}

#define EXPECT_ERROR_NAMES(call, ...)                                                   \
  do {                                                                                  \
    const std::string msg_ = errorOf([&] { call; });                                    \
    for (const std::string& part_ : std::initializer_list<std::string>{__VA_ARGS__})   \
      EXPECT_NE(msg_.find(part_), std::string::npos) << "'" << part_ << "' not in: " << msg_; \
  } while (0)

// One body of a test scene. The views point into `mesh` and `previous`; callers keep the Body
// alive and unmoved while the world uses it.
struct Body {
  TriMesh mesh;
  std::vector<Vec3> previous;  // empty: no previous-position view
  double margin = 0.0;
  std::size_t particles = 0;
  std::string name;
  BodyId id = kInvalidBody;
};

BodyDesc descOf(const Body& b) {
  BodyDesc d;
  d.triangles = b.mesh.triangles;
  d.positions = PositionView::of(b.mesh.vertices);
  if (!b.previous.empty()) d.previous = PositionView::of(b.previous);
  d.margin = b.margin;
  d.particles = b.particles;
  d.name = b.name;
  return d;
}

Body bodyOf(TriMesh mesh, const char* name) {
  Body b;
  b.mesh = std::move(mesh);
  b.name = name;
  return b;
}

void addAll(SensorWorld& w, std::vector<Body>& bodies) {
  for (Body& b : bodies) b.id = w.addBody(descOf(b));
}

struct Coverage {
  std::size_t truth = 0;    // brute-force contacts within the contact radius
  std::size_t missed = 0;   // ... not among the step's candidate pairs
};

// Brute force over every ordered pair of bodies whose bounding spheres can be within reach.
Coverage coverage(const SensorWorld& w, const std::vector<Body>& bodies, const StepResult& res) {
  std::set<std::tuple<BodyId, Index, BodyId, Index>> cand;
  for (const CandidatePair& c : res.candidates) cand.insert({c.vertex_body, c.vertex, c.triangle_body, c.triangle});
  const double factor = w.settings().motion_factor;
  std::vector<Vec3> centre(bodies.size());
  std::vector<double> radius(bodies.size()), motion(bodies.size(), 0.0);
  for (std::size_t i = 0; i < bodies.size(); ++i) {
    const Bounds bb = bounds(PositionView::of(bodies[i].mesh.vertices));
    centre[i] = bb.center();
    radius[i] = bb.radius;
    for (std::size_t v = 0; v < bodies[i].previous.size(); ++v)
      motion[i] = std::max(motion[i], (bodies[i].mesh.vertices[v] - bodies[i].previous[v]).norm());
  }
  Coverage c;
  for (std::size_t i = 0; i < bodies.size(); ++i)
    for (std::size_t j = 0; j < bodies.size(); ++j) {
      if (i == j) continue;
      const Body &a = bodies[i], &b = bodies[j];
      const double reach = radius[i] + radius[j] + a.margin + b.margin + factor * motion[i];
      if ((centre[i] - centre[j]).norm() > reach) continue;
      const auto contact_radius = [&](Index v) {
        return a.margin + b.margin +
               (a.previous.empty() ? 0.0 : factor * (a.mesh.vertices[v] - a.previous[v]).norm());
      };
      // Zero-area triangles are left out, as the world reports them degenerate (MeshReport).
      const auto zero_area = [&](Index, Index t) {
        const Triangle& tri = b.mesh.triangles[t];
        const Vec3 &p = b.mesh.vertices[tri[0]], &q = b.mesh.vertices[tri[1]], &s = b.mesh.vertices[tri[2]];
        return (q - p).cross(s - p).squaredNorm() == 0.0;
      };
      testkit::forEachContact(a.mesh.vertices, b.mesh.vertices, b.mesh.triangles, contact_radius, zero_area,
                              [&](Index v, Index t, double) {
                                ++c.truth;
                                c.missed += cand.count({a.id, v, b.id, t}) == 0;
                              });
    }
  return c;
}

// Steps `steps` times and checks full coverage after every step; returns the contacts seen.
std::size_t stepAndCheck(SensorWorld& w, const std::vector<Body>& bodies, int steps, const char* what) {
  std::size_t seen = 0;
  for (int s = 0; s < steps; ++s) {
    const StepResult& res = w.step();
    const Coverage c = coverage(w, bodies, res);
    EXPECT_EQ(c.missed, 0u) << what << ", step " << s << ": " << c.missed << " of " << c.truth << " contacts missed";
    seen += c.truth;
  }
  return seen;
}

// Two bodies pressed together: `a` as given, a unit sphere overlapping it slightly from +x
// (placed by the vertices in triangles, so stray isolated vertices do not push it away).
std::vector<Body> againstSphere(TriMesh a, double margin, double gap = -0.02) {
  std::vector<Body> bodies(2);
  bodies[0].mesh = std::move(a);
  bodies[0].name = "odd";
  bodies[0].margin = margin;
  std::vector<Vec3> used;
  for (const Triangle& t : bodies[0].mesh.triangles)
    for (Index v : t) used.push_back(bodies[0].mesh.vertices[v]);
  const Bounds bb = bounds(PositionView::of(used));
  bodies[1].mesh = makeSphere(1.0, 300).translate(Vec3(bb.hi.x() + 1.0 + gap, bb.center().y(), bb.center().z()));
  bodies[1].name = "ball";
  bodies[1].margin = margin;
  return bodies;
}

// ------------------------------------------------------------------------------------------------
// Bad meshes: rejected with a message naming the element

TEST(BadMesh, NonFiniteCoordinateNamesBodyVertexAndView) {
  for (double bad : {kNaN, kInf, -kInf}) {
    Body b = bodyOf(makeSphere(1.0, 100), "ball");
    b.mesh.vertices[5].y() = bad;
    SensorWorld w;
    ErrorCode code{};
    const std::string msg = errorOf([&] { w.addBody(descOf(b)); }, &code);
    EXPECT_EQ(code, ErrorCode::InvalidMesh);
    EXPECT_NE(msg.find("ball"), std::string::npos) << msg;
    EXPECT_NE(msg.find("vertex 5"), std::string::npos) << msg;
    EXPECT_NE(msg.find("non-finite"), std::string::npos) << msg;
    EXPECT_TRUE(w.bodyIds().empty()) << "nothing half-added";
  }
  Body b = bodyOf(makeSphere(1.0, 100), "ball");
  b.previous = b.mesh.vertices;
  b.previous[9].z() = kNaN;
  SensorWorld w;
  EXPECT_ERROR_NAMES(w.addBody(descOf(b)), "ball", "previous positions", "vertex 9");
  // Positions that turn non-finite after the body came: step() names the body, in the message and
  // in Error::body(), so that a caller (the Bullet plugin) can leave it out and step the others.
  Body good = bodyOf(makeSphere(1.0, 100), "ball");
  Body other = bodyOf(makeSphere(1.0, 100).translate({5, 0, 0}), "other");
  SensorWorld later;
  later.addBody(descOf(other));
  const BodyId id = later.addBody(descOf(good));
  later.step();
  good.mesh.vertices[7].x() = kNaN;
  later.setPositions(id, PositionView::of(good.mesh.vertices));
  try {
    later.step();
    ADD_FAILURE() << "a non-finite position must be an error";
  } catch (const Error& e) {
    EXPECT_EQ(e.body(), id);
    EXPECT_EQ(e.code(), ErrorCode::InvalidMesh);
    EXPECT_NE(e.message().find("ball"), std::string::npos) << e.message();
    EXPECT_NE(std::string(e.what()).find("vertex 7"), std::string::npos) << e.what();
  }
  later.removeBody(id);
  EXPECT_NO_THROW(later.step()) << "the others step without it";
}

// Single-precision positions take the refit's packed path (bounds.cpp, streamBoxesFloat): the same
// candidates as the same positions given in double, and a NaN or an infinity, current or previous,
// named as on the double path. Records of 12 bytes (the last vertex ends the array) and of 16.
TEST(SinglePrecision, PackedRefitFindsWhatDoublePositionsFindAndNamesBadValues) {
  for (std::size_t stride_floats : {std::size_t{3}, std::size_t{4}}) {
    std::vector<Body> bodies = againstSphere(makeTorus(1.0, 0.4, 600), 0.05, -0.1);
    std::mt19937_64 rng(99);
    std::uniform_real_distribution<double> u(-0.01, 0.01);
    std::vector<std::vector<float>> now(2), before(2);
    for (std::size_t b = 0; b < 2; ++b) {
      const std::vector<Vec3>& x = bodies[b].mesh.vertices;
      bodies[b].previous.resize(x.size());
      now[b].assign(x.size() * stride_floats, 7.0f);
      before[b].assign(x.size() * stride_floats, 7.0f);
      for (std::size_t v = 0; v < x.size(); ++v) {
        for (int k = 0; k < 3; ++k) {
          now[b][v * stride_floats + k] = static_cast<float>(x[v][k]);
          before[b][v * stride_floats + k] = static_cast<float>(x[v][k] + u(rng));
        }
        // The double world reads exactly the single-precision values.
        bodies[b].mesh.vertices[v] = Vec3(now[b][v * stride_floats], now[b][v * stride_floats + 1], now[b][v * stride_floats + 2]);
        bodies[b].previous[v] = Vec3(before[b][v * stride_floats], before[b][v * stride_floats + 1], before[b][v * stride_floats + 2]);
      }
    }
    SensorWorld doubles, singles;
    addAll(doubles, bodies);
    for (std::size_t b = 0; b < 2; ++b) {
      BodyDesc d = descOf(bodies[b]);
      d.positions = PositionView(now[b].data(), bodies[b].mesh.vertices.size(), stride_floats * sizeof(float));
      d.previous = PositionView(before[b].data(), bodies[b].mesh.vertices.size(), stride_floats * sizeof(float));
      singles.addBody(d);
    }
    for (int step = 0; step < 3; ++step) {
      const std::vector<CandidatePair> want = doubles.step().candidates;
      const std::vector<CandidatePair> got = singles.step().candidates;
      EXPECT_GT(want.size(), 100u);
      EXPECT_EQ(got, want) << "stride " << stride_floats << ", step " << step;
    }
    for (float bad : {std::numeric_limits<float>::quiet_NaN(), std::numeric_limits<float>::infinity()}) {
      for (std::vector<float>* where : {&now[1], &before[1]}) {
        const float keep = (*where)[11 * stride_floats + 2];
        (*where)[11 * stride_floats + 2] = bad;
        EXPECT_ERROR_NAMES(singles.step(), "ball", "vertex 11");
        (*where)[11 * stride_floats + 2] = keep;
        EXPECT_NO_THROW(singles.step());
      }
    }
  }
}

TEST(SinglePrecision, AJumpBeyondFloatsSquareLosesNoPairWithoutAMotionTerm) {
  // The packed refit squares motions in single precision: a vertex that jumped 2e19 or 1e20 in
  // one step (its coordinates still within kMaxCoordinate) leaves its chunk's motion infinite.
  // With motion_factor 0 the growth is the margins alone; 0 × inf made it NaN and dropped the
  // whole body pair (a review's finding). Two spheres 0.01 apart, margins 0.05: the same
  // candidates as for the same values in double.
  for (const double jump : {0.0, 2e19, 1e20}) {
    TriMesh a = makeSphere(1.0, 200), b = makeSphere(1.0, 200);
    b.translate(Vec3(2.01, 0, 0));
    std::vector<float> fa, fb, qa;
    for (const Vec3& p : a.vertices)
      for (int k = 0; k < 3; ++k) fa.push_back(static_cast<float>(p[k]));
    for (const Vec3& p : b.vertices)
      for (int k = 0; k < 3; ++k) fb.push_back(static_cast<float>(p[k]));
    qa = fa;
    qa[0] -= static_cast<float>(jump);  // vertex 0 of A, on its far side
    std::vector<Vec3> da, pa, db;
    for (std::size_t i = 0; i < a.vertices.size(); ++i) {
      da.emplace_back(fa[3 * i], fa[3 * i + 1], fa[3 * i + 2]);
      pa.emplace_back(qa[3 * i], qa[3 * i + 1], qa[3 * i + 2]);
    }
    for (std::size_t i = 0; i < b.vertices.size(); ++i) db.emplace_back(fb[3 * i], fb[3 * i + 1], fb[3 * i + 2]);
    SensorSettings settings;
    settings.motion_factor = 0.0;
    SensorWorld singles(settings), doubles(settings);
    BodyDesc A, B;
    A.triangles = a.triangles;
    B.triangles = b.triangles;
    A.margin = B.margin = 0.05;
    A.positions = PositionView(fa.data(), a.vertices.size());
    A.previous = PositionView(qa.data(), a.vertices.size());
    B.positions = PositionView(fb.data(), b.vertices.size());
    B.previous = B.positions;
    singles.addBody(A);
    singles.addBody(B);
    A.positions = PositionView::of(da);
    A.previous = PositionView::of(pa);
    B.positions = B.previous = PositionView::of(db);
    doubles.addBody(A);
    doubles.addBody(B);
    const std::vector<CandidatePair> want = doubles.step().candidates;
    EXPECT_GT(want.size(), 10u) << "jump " << jump;
    EXPECT_EQ(singles.step().candidates, want) << "jump " << jump;
  }
}

TEST(BadMesh, CoordinatesBeyondTheLimitAreRejected) {
  Body b = bodyOf(makeSphere(1.0, 100), "ball");
  b.mesh.vertices[3].x() = 1e200;  // finite, but its square overflows
  SensorWorld w;
  EXPECT_ERROR_NAMES(w.addBody(descOf(b)), "ball", "vertex 3", "beyond");
  // Positions that blow up during a simulation are caught by step(), not read as garbage.
  Body ok = bodyOf(makeSphere(1.0, 100), "ok");
  ok.id = w.addBody(descOf(ok));
  w.step();
  ok.mesh.vertices[7] *= 1e200;
  EXPECT_ERROR_NAMES(w.step(), "ok", "vertex 7");
}

TEST(BadSettings, MarginsBeyondTheCoordinatesRangeAreRejectedNamingTheBody) {
  // A review's finding (stop 46): a margin of 1e155 was taken, its squares overflowed and a pair
  // came out twice in one step; 1e308 made every step throw about the hash grid's cell size, with
  // no body named. Margins are now held to the coordinates' range, at addBody and at setMargin.
  Body b = bodyOf(makeSphere(1.0, 100), "ball");
  b.margin = 1e155;
  SensorWorld w;
  EXPECT_ERROR_NAMES(w.addBody(descOf(b)), "ball", "margin");
  b.margin = 0.02;
  const BodyId id = w.addBody(descOf(b));
  EXPECT_ERROR_NAMES(w.setMargin(id, 1e308), "ball", "margin");
  EXPECT_ERROR_NAMES(w.setMargin(id, std::numeric_limits<double>::infinity()), "ball", "margin");
  w.setMargin(id, kMaxCoordinate);  // the range's edge is a margin
  w.setMargin(id, 0.02);
  EXPECT_NO_THROW(w.step());
}

TEST(BadMesh, GivenConvexPartsAreCheckedWhenTheBodyIsAdded) {
  // A review's finding (stop 46): convex parts with a NaN radius, none at all or labels out of
  // range were taken, and the next step threw, naming the body's place in the particle budget.
  const Body b = bodyOf(makeSphere(1.0, 100), "ball");
  const auto withParts = [&](const std::function<void(ConvexParts&)>& spoil) {
    auto parts = std::make_shared<ConvexParts>();
    parts->parts.push_back(ConvexPart{Vec3::Zero(), 1.0, b.mesh.vertices.size()});
    parts->part_of.assign(b.mesh.vertices.size(), 0);
    spoil(*parts);
    BodyDesc d = descOf(b);
    d.parts = parts;
    return d;
  };
  SensorWorld w;
  EXPECT_ERROR_NAMES(w.addBody(withParts([](ConvexParts& p) { p.parts[0].radius = std::nan(""); })), "ball",
                     "part 0");
  EXPECT_ERROR_NAMES(w.addBody(withParts([](ConvexParts& p) { p.parts.clear(); })), "ball", "empty");
  EXPECT_ERROR_NAMES(w.addBody(withParts([](ConvexParts& p) { p.part_of[5] = 3; })), "ball", "vertex 5");
  EXPECT_TRUE(w.bodyIds().empty());
  w.addBody(withParts([](ConvexParts&) {}));
  EXPECT_NO_THROW(w.step());
}

TEST(BadMesh, IndexOutOfRangeNamesTriangleAndIndex) {
  Body b = bodyOf(makeSphere(1.0, 100), "ball");
  b.mesh.triangles[3][1] = 100000;
  SensorWorld w;
  ErrorCode code{};
  const std::string msg = errorOf([&] { w.addBody(descOf(b)); }, &code);
  EXPECT_EQ(code, ErrorCode::InvalidMesh);
  for (const char* part : {"ball", "triangle 3", "100000", "out of range"})
    EXPECT_NE(msg.find(part), std::string::npos) << msg;
  // The largest valid index plus one is out of range too.
  b.mesh.triangles[3][1] = static_cast<Index>(b.mesh.vertices.size());
  EXPECT_ERROR_NAMES(w.addBody(descOf(b)), "triangle 3", "out of range");
}

TEST(BadMesh, NoTrianglesOrNoVerticesIsAnError) {
  SensorWorld w;
  Body b = bodyOf(makeSphere(1.0, 100), "ball");
  b.mesh.triangles.clear();
  EXPECT_ERROR_NAMES(w.addBody(descOf(b)), "ball", "no triangles");
  Body empty;
  empty.name = "empty";
  EXPECT_ERROR_NAMES(w.addBody(descOf(empty)), "empty", "no vertices");
  EXPECT_ERROR_NAMES(MeshTopology({}, 3), "no triangles");
}

TEST(BadMesh, AllTrianglesDegenerateIsAnError) {
  SensorWorld w;
  Body line;
  line.name = "line";
  line.mesh.vertices = {Vec3(0, 0, 0), Vec3(1, 0, 0), Vec3(2, 0, 0)};
  line.mesh.triangles = {{0, 1, 2}, {0, 0, 1}};
  EXPECT_ERROR_NAMES(w.addBody(descOf(line)), "line", "degenerate");
}

// ------------------------------------------------------------------------------------------------
// Odd meshes: accepted, reported, and detection still works

TEST(OddMesh, SingleTriangleWorks) {
  std::vector<Body> bodies(2);
  for (int i = 0; i < 2; ++i) {
    bodies[i].mesh.vertices = {Vec3(0, 0, 0), Vec3(1, 0, 0), Vec3(0, 1, 0)};
    bodies[i].mesh.triangles = {{0, 1, 2}};
    bodies[i].margin = 0.05;
    bodies[i].name = "tri" + std::to_string(i);
  }
  bodies[1].mesh.translate(Vec3(0.2, 0.2, 0.05));
  SensorWorld w;
  addAll(w, bodies);
  EXPECT_GT(stepAndCheck(w, bodies, 3, "single triangles"), 0u);
  EXPECT_EQ(w.particleCount(bodies[0].id), 1u);
  EXPECT_EQ(w.report(bodies[0].id).boundary_edges, 3u);
  EXPECT_EQ(w.lastResult().stats.flagged_pairs, 1u);
}

TEST(OddMesh, DegenerateAndSliverTrianglesAreReportedAndTheBodyStillWorks) {
  TriMesh m = makeSphere(1.0, 300);
  const Index n = static_cast<Index>(m.vertices.size());
  m.triangles.push_back({0, 0, 1});  // repeated index
  m.vertices.push_back(0.5 * (m.vertices[1] + m.vertices[2]));
  m.triangles.push_back({1, 2, n});  // collinear: zero area
  m.vertices.push_back(m.vertices[1] + 1e-5 * (m.vertices[2] - m.vertices[1]).cross(Vec3(0, 0, 1)).normalized() +
                       0.5 * (m.vertices[3] - m.vertices[1]));
  m.triangles.push_back({1, 3, n + 1});  // sliver: altitude far below 1e-3 × longest edge
  std::vector<Body> bodies = againstSphere(m, 0.02);
  SensorWorld w;
  addAll(w, bodies);
  const MeshReport& r = w.report(bodies[0].id);
  EXPECT_EQ(r.degenerate_triangles, 2u) << r.summary();
  EXPECT_EQ(r.first_degenerate_triangle, m.triangles.size() - 3) << r.summary();
  EXPECT_GE(r.sliver_triangles, 1u) << r.summary();
  EXPECT_GT(stepAndCheck(w, bodies, 3, "degenerate and sliver"), 0u);
}

TEST(OddMesh, DuplicateVerticesAreReportedAndTheBodyStillWorks) {
  // A sphere whose first ring is unwelded: the seam carries duplicate positions.
  TriMesh m = makeSphere(1.0, 300);
  const std::size_t n = m.vertices.size();
  std::size_t dup = 0;
  for (Triangle& t : m.triangles)
    for (Index& v : t)
      if (v >= 1 && v <= 10 && (&t - m.triangles.data()) % 2 == 0) {
        m.vertices.push_back(m.vertices[v]);
        v = static_cast<Index>(m.vertices.size() - 1);
        ++dup;
      }
  ASSERT_GT(dup, 0u);
  std::vector<Body> bodies = againstSphere(m, 0.02);
  bodies[1].mesh = makeSphere(1.0, 300).translate(Vec3(0, 0, 2.0));  // against the unwelded pole
  SensorWorld w;
  addAll(w, bodies);
  EXPECT_EQ(w.report(bodies[0].id).duplicate_vertices, m.vertices.size() - n) << w.report(bodies[0].id).summary();
  EXPECT_GT(stepAndCheck(w, bodies, 3, "duplicate vertices"), 0u);
}

TEST(OddMesh, IsolatedVerticesAreReportedAndNeverCarryAParticle) {
  TriMesh m = makeSphere(1.0, 300);
  const std::size_t used = m.vertices.size();
  m.vertices.insert(m.vertices.begin() + 0, Vec3(0.9, 0, 0));  // isolated, shifts every index
  for (Triangle& t : m.triangles)
    for (Index& v : t) ++v;
  m.vertices.push_back(Vec3(5, 5, 5));
  m.vertices.push_back(Vec3(1.05, 0, 0));  // isolated, right where the other body touches
  std::vector<Body> bodies = againstSphere(m, 0.02);
  bodies[0].particles = used;  // every vertex that lies in a triangle
  SensorWorld w;
  addAll(w, bodies);
  EXPECT_EQ(w.report(bodies[0].id).isolated_vertices, 3u);
  EXPECT_GT(stepAndCheck(w, bodies, 2, "isolated vertices"), 0u);
  EXPECT_EQ(w.particleCount(bodies[0].id), used);
  const MeshTopology& topo = w.topology(bodies[0].id);
  for (const ParticleState& p : w.particles())
    if (p.body == bodies[0].id) {
      EXPECT_FALSE(topo.vertexTriangles(p.vertex).empty()) << "particle on isolated vertex";
    }
  bodies[0].particles = used + 1;
  EXPECT_ERROR_NAMES(w.addBody(descOf(bodies[0])), "particles", std::to_string(used));
}

TEST(OddMesh, NonManifoldEdgesAreReportedAndTheBodyStillWorks) {
  // Three patches sharing one edge (a paddle wheel), the fin reaching toward the other body.
  TriMesh m;
  const std::vector<Vec3> blades = {Vec3(1, 0, 0), Vec3(-0.5, 0.8, 0), Vec3(-0.5, -0.8, 0)};
  m.vertices = {Vec3(0, 0, -1), Vec3(0, 0, 1)};
  for (const Vec3& d : blades) {
    const Index a = static_cast<Index>(m.vertices.size());
    m.vertices.push_back(d + Vec3(0, 0, -1));
    m.vertices.push_back(d + Vec3(0, 0, 1));
    m.triangles.push_back({0, a, a + 1});
    m.triangles.push_back({0, a + 1, 1});
  }
  std::vector<Body> bodies = againstSphere(m, 0.02);
  // A cloth patch hovering over the first blade (plane y = 0) instead of the ball.
  const double kHalfPi = 1.57079632679489661923;
  bodies[1].mesh = makePatch(0.6, 1.0, 7, 11).rotate(Vec3(1, 0, 0), kHalfPi).translate(Vec3(0.5, 0.02, 0));
  SensorWorld w;
  addAll(w, bodies);
  EXPECT_EQ(w.report(bodies[0].id).non_manifold_edges, 1u) << w.report(bodies[0].id).summary();
  EXPECT_GT(stepAndCheck(w, bodies, 3, "non-manifold"), 0u);
}

TEST(OddMesh, DisconnectedPiecesInOneBodyAreReportedAndAllDetected) {
  TriMesh m = makeSphere(1.0, 200);
  TriMesh second = makeSphere(0.5, 120).translate(Vec3(0, 3, 0));
  const Index offset = static_cast<Index>(m.vertices.size());
  m.vertices.insert(m.vertices.end(), second.vertices.begin(), second.vertices.end());
  for (Triangle t : second.triangles) m.triangles.push_back({t[0] + offset, t[1] + offset, t[2] + offset});
  std::vector<Body> bodies = againstSphere(m, 0.02);
  Body third;
  third.mesh = makeSphere(0.5, 120).translate(Vec3(0, 4.0, 0));  // touches the small piece
  third.margin = 0.02;
  third.name = "third";
  bodies.push_back(third);
  SensorWorld w;
  addAll(w, bodies);
  EXPECT_EQ(w.report(bodies[0].id).components, 2u);
  EXPECT_GT(stepAndCheck(w, bodies, 3, "two pieces"), 0u);
  std::set<BodyId> touched;
  for (const FlaggedPair& f : w.lastResult().flagged) touched.insert(f.body_a == bodies[0].id ? f.body_b : f.body_a);
  EXPECT_EQ(touched.count(bodies[1].id) + touched.count(bodies[2].id), 2u) << "both pieces flagged";
}

TEST(OddMesh, InconsistentWindingIsReportedAndTheBodyStillWorks) {
  TriMesh m = makeSphere(1.0, 300);
  for (std::size_t t = 0; t < m.triangles.size(); t += 3) std::swap(m.triangles[t][1], m.triangles[t][2]);
  std::vector<Body> bodies = againstSphere(m, 0.02);
  SensorWorld w;
  addAll(w, bodies);
  EXPECT_GT(w.report(bodies[0].id).inconsistent_winding_edges, 0u);
  EXPECT_GT(stepAndCheck(w, bodies, 3, "inconsistent winding"), 0u);
}

// ------------------------------------------------------------------------------------------------
// Settings out of range: named

TEST(BadSettings, EffectiveRadiusNegativeIsNamedAndTooSmallIsClampedAboveMu) {
  SensorSettings s;
  s.r_eff = -1.0;
  EXPECT_ERROR_NAMES(SensorWorld w(s), "r_eff");
  s.r_eff = kNaN;
  EXPECT_ERROR_NAMES(SensorWorld w(s), "r_eff");
  // Thesis §5.1.3: R_eff ≤ μ never pulls a touching pair together; a tiny setting is raised.
  s.r_eff = 1e-9;
  SensorWorld w(s);
  std::vector<Body> bodies = againstSphere(makeSphere(1.0, 300), 0.02);
  addAll(w, bodies);
  const StepResult& res = w.step();
  EXPECT_GT(res.stats.r_eff, w.mu(bodies[0].id, bodies[1].id));
}

TEST(BadSettings, NegativeOrZeroSizesAreNamed) {
  SensorWorld w;
  Body b = bodyOf(makeSphere(1.0, 100), "ball");
  for (double m : {-0.1, kNaN, kInf}) {
    b.margin = m;
    EXPECT_ERROR_NAMES(w.addBody(descOf(b)), "ball", "margin");
  }
  b.margin = 0.0;
  b.id = w.addBody(descOf(b));
  EXPECT_ERROR_NAMES(w.setMargin(b.id, -1.0), "ball", "margin");
  EXPECT_ERROR_NAMES(makeSphere(0.0, 100), "radius");
  EXPECT_ERROR_NAMES(makeSphere(-1.0, 100), "radius");
  EXPECT_ERROR_NAMES(makeBox(Vec3(1, 0, 1), 100), "half extent");
  const auto named = [](const char* name, const std::function<void(SensorSettings&)>& set) {
    SensorSettings s;
    set(s);
    EXPECT_ERROR_NAMES(SensorWorld world(s), name);
  };
  named("mu_edge_factor", [](SensorSettings& s) { s.mu_edge_factor = 0.0; });
  named("max_rounds", [](SensorSettings& s) { s.max_rounds = 0; });
  named("rounds_per_step", [](SensorSettings& s) { s.rounds_per_step = -1; });
  named("motion_factor", [](SensorSettings& s) { s.motion_factor = -2.0; });
  named("ahead_steps", [](SensorSettings& s) { s.ahead_steps = 0.0; });
  named("ahead_steps", [](SensorSettings& s) { s.ahead_steps = std::numeric_limits<double>::quiet_NaN(); });
  named("motion_bound", [](SensorSettings& s) { s.motion_bound = static_cast<MotionBound>(7); });
  named("chunk_vertices", [](SensorSettings& s) { s.chunk_vertices = 3; });
  named("check_every", [](SensorSettings& s) { s.repartition.check_every = 0; });
  named("area_trigger", [](SensorSettings& s) { s.repartition.area_trigger = 0.0; });
  named("edge_stretch_trigger", [](SensorSettings& s) { s.repartition.edge_stretch_trigger = -1.0; });
  named("concavity", [](SensorSettings& s) { s.decomposition.concavity = 0.0; });
  named("concavity", [](SensorSettings& s) { s.decomposition.concavity = -0.1; });
  named("min_parts", [](SensorSettings& s) { s.decomposition.min_parts = 0; });
  named("max_hull_vertices", [](SensorSettings& s) { s.decomposition.max_hull_vertices = 3; });
  named("max_lloyd_iterations", [](SensorSettings& s) { s.partition.max_lloyd_iterations = 0; });
}

TEST(BadSettings, NormalWeightAndEpsilonOutOfRangeAreNamed) {
  for (double eps : {0.0, 1.0, -0.01, 1.5, kNaN, kInf}) {
    SensorSettings s;
    s.partition.epsilon = eps;
    EXPECT_ERROR_NAMES(SensorWorld w(s), "epsilon");
    TriMesh m = makeSphere(1.0, 100);
    const MeshTopology topo(m.triangles, m.vertices.size());
    EXPECT_ERROR_NAMES(partitionLBG(topo, PositionView::of(m.vertices), 4, s.partition), "epsilon");
  }
  for (double weight : {-0.5, kNaN, kInf, -kInf}) {
    SensorSettings s;
    s.partition.normal_weight = weight;
    EXPECT_ERROR_NAMES(SensorWorld world(s), "normal_weight");
  }
  SensorSettings s;
  s.partition.normal_weight = 0.0;  // positions only: legal
  EXPECT_EQ(errorOf([&] { SensorWorld w(s); }), "<no error>");
}

// BodyDesc::particles = 0 is "automatic", never "no sensors": every body gets at least one
// particle, and the only way to ask for zero is partitionLBG's count, which says so.
TEST(BadSettings, ZeroParticlesMeansAutomaticAndNeverNoSensor) {
  SensorWorld w;
  EXPECT_EQ(w.step().stats.particles, 0u) << "an empty world steps";
  std::vector<Body> bodies = againstSphere(makeSphere(1.0, 300), 0.02);
  Body tiny;
  tiny.mesh.vertices = {Vec3(0, 0, 0), Vec3(0.01, 0, 0), Vec3(0, 0.01, 0)};
  tiny.mesh.triangles = {{0, 1, 2}};
  tiny.mesh.translate(Vec3(0, 5, 0));
  bodies.push_back(tiny);
  for (Body& b : bodies) b.particles = 0;
  addAll(w, bodies);
  stepAndCheck(w, bodies, 2, "automatic budget");
  for (const Body& b : bodies) EXPECT_GE(w.particleCount(b.id), 1u) << b.name;
  for (const Body& b : bodies) w.removeBody(b.id);
  EXPECT_EQ(w.step().stats.particles, 0u) << "a world emptied again steps";
  TriMesh m = makeSphere(1.0, 100);
  const MeshTopology topo(m.triangles, m.vertices.size());
  EXPECT_ERROR_NAMES(partitionLBG(topo, PositionView::of(m.vertices), 0), "count = 0");
}

TEST(BadSettings, MoreParticlesThanVerticesIsNamedAndExactlyAllVerticesWorks) {
  std::vector<Body> bodies = againstSphere(makeSphere(1.0, 60), 0.05);
  bodies[0].name = "small";
  bodies[0].particles = bodies[0].mesh.vertices.size() + 1;
  SensorWorld w;
  EXPECT_ERROR_NAMES(w.addBody(descOf(bodies[0])), "small", "particles",
                     std::to_string(bodies[0].mesh.vertices.size()));
  bodies[0].particles = bodies[0].mesh.vertices.size();  // one region per vertex
  addAll(w, bodies);
  EXPECT_GT(stepAndCheck(w, bodies, 2, "one particle per vertex"), 0u);
  EXPECT_EQ(w.particleCount(bodies[0].id), bodies[0].mesh.vertices.size());
}

// ------------------------------------------------------------------------------------------------
// Hard conditions

// Flags keyed by body order, not id, so worlds with different ids compare.
using FlagSet = std::set<std::tuple<std::size_t, Index, std::size_t, Index>>;
FlagSet flagsOf(const StepResult& res, const std::vector<Body>& bodies) {
  const auto order = [&](BodyId id) {
    for (std::size_t i = 0; i < bodies.size(); ++i)
      if (bodies[i].id == id) return i;
    return bodies.size();
  };
  FlagSet out;
  for (const FlaggedPair& f : res.flagged) out.insert({order(f.body_a), f.region_a, order(f.body_b), f.region_b});
  return out;
}

// Seeded noise of `amplitude` on every coordinate. The generated shapes are exactly symmetric, so
// LBG and the particle walk meet exact ties there, which a one-ulp change (a translated or scaled
// copy) breaks differently; real meshes have no such ties.
TriMesh& jitter(TriMesh& m, unsigned seed, double amplitude) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(-amplitude, amplitude);
  for (Vec3& v : m.vertices)
    for (int k = 0; k < 3; ++k) v[k] += u(rng);
  return m;
}

std::vector<Body> touchingScene() {
  std::vector<Body> bodies(3);
  bodies[0].mesh = makeSphere(1.0, 400);
  bodies[1].mesh = makeTorus(1.0, 0.3, 400).rotate(Vec3(1, 0, 0), 1.2).translate(Vec3(2.25, 0.1, 0));
  bodies[2].mesh = makeBox(Vec3(0.5, 0.5, 0.5), 300).translate(Vec3(0.1, 1.49, 0.1));
  for (std::size_t i = 0; i < bodies.size(); ++i) {
    jitter(bodies[i].mesh, 7 + static_cast<unsigned>(i), 0.01);
    bodies[i].margin = 0.03;
    bodies[i].name = "b" + std::to_string(i);
  }
  return bodies;
}

TEST(HardConditions, FarFromOriginAndSmallScaleGiveTheSameFlags) {
  const auto run = [](const Vec3& offset, double scale, FlagSet& flags, std::size_t& contacts) {
    std::vector<Body> bodies = touchingScene();
    for (Body& b : bodies) {
      b.mesh.scale(scale).translate(offset);
      b.margin *= scale;
    }
    SensorWorld w;
    addAll(w, bodies);
    contacts = stepAndCheck(w, bodies, 3, "transformed scene");
    flags = flagsOf(w.lastResult(), bodies);
  };
  FlagSet at_origin, far, small, far_small;
  std::size_t c0 = 0, c1 = 0, c2 = 0, c3 = 0;
  run(Vec3::Zero(), 1.0, at_origin, c0);
  run(Vec3(1e5, -1e5, 1e5), 1.0, far, c1);
  run(Vec3::Zero(), 1e-3, small, c2);
  run(Vec3(1e5, 0, 0), 1e-3, far_small, c3);
  EXPECT_GT(c0, 0u);
  EXPECT_FALSE(at_origin.empty());
  EXPECT_EQ(far, at_origin) << "offset 1e5";
  EXPECT_EQ(small, at_origin) << "scale 1e-3";
  EXPECT_EQ(far_small, at_origin) << "offset 1e5, scale 1e-3";
  EXPECT_GT(c1, 0u);
  EXPECT_GT(c2, 0u);
  EXPECT_GT(c3, 0u);
}

// Thesis Fig. 3-12: a body that crosses several regions of the other in one step. With the
// previous positions given, the motion term widens the contact radius; nothing inside it is lost.
TEST(HardConditions, FastBodyCrossingSeveralRegionsPerStepLosesNoContact) {
  std::vector<Body> bodies(2);
  bodies[0].mesh = makePatch(8.0, 8.0, 33, 33);  // the floor: 256 regions of about 0.5 × 0.5
  bodies[0].particles = 256;
  bodies[0].name = "floor";
  bodies[1].mesh = makeIcosphere(0.4, 2);
  bodies[1].name = "bullet";
  for (Body& b : bodies) b.margin = 0.02;
  const Vec3 start(-3.5, -3.0, 0.41);
  const Vec3 velocity(0.8, 0.6, -0.01);  // one length unit per step: two to three regions
  Body& fast = bodies[1];
  const TriMesh rest = fast.mesh;
  const auto place = [&](int step) {
    fast.mesh = rest;
    fast.mesh.translate(start + double(step) * velocity);
    fast.previous = rest.vertices;
    for (Vec3& p : fast.previous) p += start + double(step - 1) * velocity;
  };
  place(0);
  SensorWorld w;
  addAll(w, bodies);
  std::size_t contacts = 0, with_contacts = 0;
  for (int s = 0; s < 5; ++s) {
    place(s);
    w.setPositions(fast.id, PositionView::of(fast.mesh.vertices), PositionView::of(fast.previous));
    const StepResult& res = w.step();
    const Coverage c = coverage(w, bodies, res);
    EXPECT_EQ(c.missed, 0u) << "step " << s << ": " << c.missed << " of " << c.truth << " missed";
    contacts += c.truth;
    with_contacts += c.truth > 0;
  }
  EXPECT_GE(with_contacts, 4u) << "the motion term must put contacts in range at most steps";
  EXPECT_GT(contacts, 100u);
}

/// The motion-bound tests' bodies: a 6 × 6 sheet of 625 vertices (64 particles) and a ball of
/// radius 0.4, margins 0.02.
std::vector<Body> sheetAndBall() {
  std::vector<Body> bodies(2);
  bodies[0].mesh = makePatch(6.0, 6.0, 25, 25);
  bodies[0].particles = 64;
  bodies[0].name = "sheet";
  bodies[1].mesh = makeIcosphere(0.4, 2);
  bodies[1].name = "ball";
  for (Body& b : bodies) b.margin = 0.02;
  return bodies;
}

/// sheetAndBall() in motion for the motion-bound tests: at step k the sheet is raised by sheet_dz·k
/// and the ball moved to ball_start + ball_velocity·k, every vertex with its own random jitter.
/// moveTo(k) makes the positions of step k current and those of the step before previous, and
/// hands both to `worlds`.
struct FlyingBall {
  std::vector<Body> bodies = sheetAndBall();
  const TriMesh sheet_rest = bodies[0].mesh, ball_rest = bodies[1].mesh;
  std::mt19937 rng;
  std::uniform_real_distribution<double> jitter;
  double sheet_dz;
  Vec3 ball_start, ball_velocity;

  FlyingBall(unsigned seed, double jitter_size, double sheet_dz_, const Vec3& start, const Vec3& velocity)
      : rng(seed), jitter(-jitter_size, jitter_size), sheet_dz(sheet_dz_), ball_start(start), ball_velocity(velocity) {
    pose(0);
  }
  void moveTo(int step, std::initializer_list<SensorWorld*> worlds) {
    for (Body& b : bodies) b.previous = b.mesh.vertices;
    pose(step);
    for (SensorWorld* w : worlds)
      for (Body& b : bodies) w->setPositions(b.id, PositionView::of(b.mesh.vertices), PositionView::of(b.previous));
  }

 private:
  void pose(int step) {
    bodies[0].mesh.vertices = sheet_rest.vertices;
    for (Vec3& p : bodies[0].mesh.vertices) p += Vec3(jitter(rng), jitter(rng), sheet_dz * step + jitter(rng));
    bodies[1].mesh.vertices = ball_rest.vertices;
    for (Vec3& p : bodies[1].mesh.vertices)
      p += ball_start + step * ball_velocity + Vec3(jitter(rng), jitter(rng), jitter(rng));
  }
};

/// Whether vertex v of `a` comes within r of triangle `tri` of `b` at one of 65 times of the step,
/// both moving linearly from their previous to their current positions (a pair found at a sampled
/// time certainly meets; the bounds must keep it).
bool meetsDuringStep(const Body& a, Index v, const Body& b, const Triangle& tri, double r) {
  // Every sampled point lies in the box of its path's two ends: boxes farther apart than r along
  // an axis (by more than the distance's rounding) cannot meet, and most pairs end here.
  Vec3 v_lo = a.previous[v].cwiseMin(a.mesh.vertices[v]), v_hi = a.previous[v].cwiseMax(a.mesh.vertices[v]);
  Vec3 t_lo = Vec3::Constant(std::numeric_limits<double>::infinity()), t_hi = -t_lo;
  for (Index c : tri) {
    t_lo = t_lo.cwiseMin(b.previous[c]).cwiseMin(b.mesh.vertices[c]);
    t_hi = t_hi.cwiseMax(b.previous[c]).cwiseMax(b.mesh.vertices[c]);
  }
  const double apart = r * (1.0 + 1e-6);
  if (((v_lo - t_hi).array() >= apart).any() || ((t_lo - v_hi).array() >= apart).any()) return false;
  for (int k = 0; k <= 64; ++k) {
    const double s = k / 64.0;
    const auto at = [&](const Body& x, Index u) { return Vec3((1 - s) * x.previous[u] + s * x.mesh.vertices[u]); };
    if (testkit::pointTriangleDistance(at(a, v), at(b, tri[0]), at(b, tri[1]), at(b, tri[2])) < r) return true;
  }
  return false;
}

using PairKey = std::tuple<BodyId, Index, BodyId, Index>;

/// Every (vertex, triangle) pair of two bodies, both directions, that meetsDuringStep at radius r.
std::vector<PairKey> meetingPairs(const std::vector<Body>& bodies, double r) {
  std::vector<PairKey> out;
  for (int i = 0; i < 2; ++i) {
    const Body &a = bodies[i], &b = bodies[1 - i];
    for (Index v = 0; v < a.mesh.vertices.size(); ++v)
      for (Index t = 0; t < b.mesh.triangles.size(); ++t)
        if (meetsDuringStep(a, v, b, b.mesh.triangles[t], r)) out.emplace_back(a.id, v, b.id, t);
  }
  return out;
}

std::set<PairKey> candidateSet(const StepResult& res) {
  std::set<PairKey> out;
  for (const CandidatePair& c : res.candidates) out.insert({c.vertex_body, c.vertex, c.triangle_body, c.triangle});
  return out;
}

// MotionBound::Swept: every (vertex, triangle) pair that comes within the margins at some time of
// the step (both moving linearly) is a candidate. Reference: the distance at 65 times of the step
// (a pair found at a sampled time certainly meets the margins), by brute force. Both bodies move,
// every vertex with its own random jitter, and the ball crosses several regions per step.
TEST(HardConditions, SweptBoundKeepsEveryPairThatMeetsDuringTheStep) {
  FlyingBall fly(7, 0.03, 0.1, Vec3(-2.5, -1.0, 1.2), Vec3(0.9, 0.5, -0.35));
  std::vector<Body>& bodies = fly.bodies;
  SensorSettings settings;
  settings.motion_bound = MotionBound::Swept;
  SensorWorld swept(settings), radius;
  addAll(swept, bodies);
  for (Body& b : bodies) b.id = radius.addBody(descOf(b));
  std::size_t met = 0, candidates_swept = 0, candidates_radius = 0;
  for (int step = 1; step <= 6; ++step) {
    fly.moveTo(step, {&swept, &radius});
    const StepResult& res = swept.step();
    const std::set<PairKey> cand = candidateSet(res);
    candidates_swept += res.candidates.size();
    candidates_radius += radius.step().candidates.size();
    for (const auto& [vb, v, tb, t] : meetingPairs(bodies, bodies[0].margin + bodies[1].margin)) {
      ++met;
      EXPECT_EQ(cand.count({vb, v, tb, t}), 1u)
          << "step " << step << ": body " << vb << " vertex " << v << " meets body " << tb << " triangle " << t;
    }
  }
  EXPECT_GT(met, 50u) << "the ball must cross the sheet";
  // A fast vertex reaches half its step about its path's midpoint, not twice its step about its end.
  EXPECT_LT(candidates_swept, candidates_radius / 2) << "swept " << candidates_swept << ", radius " << candidates_radius;
}

// The sensor stage where the candidate stage ends with boxes, not with the exact distance: with
// MotionBound::Swept a pair whose boxes meet is a candidate (it may meet during the step), so what
// the sensor axis drops (a vertex beyond the triangle chunk's extent along it, a pair whose extents
// along it lie apart) never reaches the exact test. Same scene as above, both flagging modes: each
// keeps every pair that meets during the step (the 65-time brute force), and the sensors hand over
// strictly fewer pairs than the boxes alone. (With MotionBound::Radius both end with the exact
// distance and hand over the same pairs: SensorDecision.ObliqueCurvedContactSameCandidatesFewerProbes.)
TEST(HardConditions, SweptBoundTheSensorsHandOverFewerPairsThanTheBoxesAlone) {
  FlyingBall fly(11, 0.03, 0.1, Vec3(-2.5, -1.0, 1.2), Vec3(0.9, 0.5, -0.35));
  std::vector<Body>& bodies = fly.bodies;
  SensorSettings sensors_settings, bounds_settings;
  sensors_settings.motion_bound = bounds_settings.motion_bound = MotionBound::Swept;
  bounds_settings.flagging = Flagging::Bounds;
  SensorWorld sensors(sensors_settings), bounds(bounds_settings);
  addAll(sensors, bodies);
  for (Body& b : bodies) ASSERT_EQ(bounds.addBody(descOf(b)), b.id);
  std::size_t met = 0, by_sensors = 0, by_bounds = 0, dropped = 0;
  for (int step = 1; step <= 6; ++step) {
    fly.moveTo(step, {&sensors, &bounds});
    const std::vector<PairKey> meeting = meetingPairs(bodies, bodies[0].margin + bodies[1].margin);
    met += meeting.size();
    for (SensorWorld* w : {&sensors, &bounds}) {
      const StepResult& res = w->step();
      const std::set<PairKey> cand = candidateSet(res);
      (w == &sensors ? by_sensors : by_bounds) += res.candidates.size();
      if (w == &sensors) dropped += res.stats.vertices_dropped + res.stats.chunks_dropped;
      for (const auto& [vb, v, tb, t] : meeting)
        EXPECT_EQ(cand.count({vb, v, tb, t}), 1u)
            << (w == &sensors ? "sensors" : "bounds") << ", step " << step << ": body " << vb << " vertex " << v
            << " meets body " << tb << " triangle " << t;
    }
  }
  std::cout << "[ swept ] pairs that meet " << met << "; candidates: sensors " << by_sensors << ", bounds " << by_bounds
            << "; vertices and chunks the slab dropped " << dropped << "\n";
  EXPECT_GT(met, 50u) << "the ball must cross the sheet";
  EXPECT_GT(dropped, 0u);
  EXPECT_LT(by_sensors, by_bounds) << "the sensor axis must drop pairs the boxes keep";
}

// SensorSettings::meeting_pairs with MotionBound::Radius: the candidates hold every pair of the
// radius bound and every pair that meets within the margins during the step (the 65-time brute
// force above), and no pair farther now than either reach. The sheet barely moves and the ball
// flies through it: a sheet vertex that a ball triangle sweeps over is within the margins of it
// during the step but not within the radius bound's reach now, whose motion term is the sheet
// vertex's own.
TEST(HardConditions, MeetingPairsJoinTheRadiusBoundAndTheSweptOne) {
  // motion_factor 0.5 too: the probes must still reach each vertex's own path.
  for (const double factor : {2.0, 0.5}) {
    FlyingBall fly(5, 0.004, 0.0, Vec3(-2.5, -1.0, 1.2), Vec3(0.9, 0.5, -0.35));
    std::vector<Body>& bodies = fly.bodies;
    SensorSettings plain;
    plain.motion_factor = factor;
    SensorSettings settings = plain;
    settings.meeting_pairs = true;
    SensorWorld meeting(settings), radius(plain);
    addAll(meeting, bodies);
    for (Body& b : bodies) b.id = radius.addBody(descOf(b));
    using Key = std::tuple<BodyId, Index, BodyId, Index>;
    std::size_t met = 0, met_beyond_radius = 0, in_radius = 0, candidates = 0;
    for (int step = 1; step <= 6; ++step) {
      fly.moveTo(step, {&meeting, &radius});
      std::set<Key> got, got_radius;
      for (const CandidatePair& c : meeting.step().candidates) got.insert({c.vertex_body, c.vertex, c.triangle_body, c.triangle});
      for (const CandidatePair& c : radius.step().candidates)
        got_radius.insert({c.vertex_body, c.vertex, c.triangle_body, c.triangle});
      candidates += got.size();
      in_radius += got_radius.size();
      for (const Key& k : got_radius) EXPECT_EQ(got.count(k), 1u) << "step " << step << ": a pair of the radius bound is missing";
      const double r = bodies[0].margin + bodies[1].margin;
      for (int i = 0; i < 2; ++i) {
        const Body &a = bodies[i], &b = bodies[1 - i];
        for (Index v = 0; v < a.mesh.vertices.size(); ++v) {
          const double dv = (a.mesh.vertices[v] - a.previous[v]).norm();
          for (Index t = 0; t < b.mesh.triangles.size(); ++t) {
            const Triangle& tri = b.mesh.triangles[t];
            const Key key{a.id, v, b.id, t};
            if (got.count(key) != 0) {
              double dt = 0.0;
              for (Index c : tri) dt = std::max(dt, (b.mesh.vertices[c] - b.previous[c]).norm());
              const double now = testkit::pointTriangleDistance(a.mesh.vertices[v], b.mesh.vertices[tri[0]],
                                                                b.mesh.vertices[tri[1]], b.mesh.vertices[tri[2]]);
              EXPECT_LT(now, std::max(r + factor * dv, r + dv + dt) * (1.0 + 1e-4) + 1e-5)
                  << "step " << step << ": a pair beyond both reaches";
            }
            if (!meetsDuringStep(a, v, b, tri, r)) continue;
            ++met;
            met_beyond_radius += got_radius.count(key) == 0;
            EXPECT_EQ(got.count(key), 1u) << "motion_factor " << factor << ", step " << step << ": " << a.name
                                          << " vertex " << v << " meets " << b.name << " triangle " << t;
          }
        }
      }
    }
    std::printf("meeting pairs, motion_factor %.1f: %zu met during the steps, %zu of them beyond the radius bound; "
                "candidates %zu (radius bound %zu)\n", factor, met, met_beyond_radius, candidates, in_radius);
    EXPECT_GT(met, 50u) << "the ball must cross the sheet";
    EXPECT_GT(met_beyond_radius, 10u) << "the radius bound alone must miss some: else the test shows nothing";
  }
}

TEST(HardConditions, AheadBoundKeepsTheMarginsAndWhatTheMotionHeadsInto) {
  // A ball flies at a sheet, fast (0.3 per step against margins of 0.02), and through it: of the
  // pairs inside Bullet's radius (margins + 2|dx|, MotionBound::Radius) the ahead bound must keep
  // every pair within the margins now and every pair whose paths ahead (x + s·dx, s in [0, 1], for
  // the vertex and each corner) come within the margins, and nothing Radius does not keep.
  FlyingBall fly(11, 0.02, 0.02, Vec3(-0.6, 0.1, 1.5), Vec3(0.12, 0.0, -0.3));
  std::vector<Body>& bodies = fly.bodies;
  SensorSettings settings;
  settings.motion_bound = MotionBound::Ahead;
  SensorWorld ahead(settings), radius;
  addAll(ahead, bodies);
  for (Body& b : bodies) b.id = radius.addBody(descOf(b));
  std::size_t within_margins = 0, headed = 0, candidates_ahead = 0, candidates_radius = 0;
  for (int step = 1; step <= 9; ++step) {
    fly.moveTo(step, {&ahead, &radius});
    using Key = std::tuple<BodyId, Index, BodyId, Index>;
    std::set<Key> kept_ahead, kept_radius;
    for (const CandidatePair& c : ahead.step().candidates) kept_ahead.insert({c.vertex_body, c.vertex, c.triangle_body, c.triangle});
    for (const CandidatePair& c : radius.step().candidates) kept_radius.insert({c.vertex_body, c.vertex, c.triangle_body, c.triangle});
    candidates_ahead += kept_ahead.size();
    candidates_radius += kept_radius.size();
    for (const Key& k : kept_ahead) EXPECT_EQ(kept_radius.count(k), 1u) << "step " << step << ": ahead keeps a pair Radius does not";
    const double r = bodies[0].margin + bodies[1].margin;
    for (int i = 0; i < 2; ++i) {
      const Body &a = bodies[i], &b = bodies[1 - i];
      for (Index v = 0; v < a.mesh.vertices.size(); ++v) {
        const double reach = r + 2.0 * (a.mesh.vertices[v] - a.previous[v]).norm();
        for (Index t = 0; t < b.mesh.triangles.size(); ++t) {
          const Triangle& tri = b.mesh.triangles[t];
          const auto at = [&](const Body& x, Index u, double s) {
            return Vec3(x.mesh.vertices[u] + s * (x.mesh.vertices[u] - x.previous[u]));
          };
          const auto distance = [&](double s) {
            return testkit::pointTriangleDistance(at(a, v, s), at(b, tri[0], s), at(b, tri[1], s), at(b, tri[2], s));
          };
          const double now = distance(0.0);
          if (now >= reach) continue;  // outside Bullet's radius: no bound keeps it
          bool meets = now < r;
          within_margins += meets ? 1 : 0;
          for (int k = 1; k <= 64 && !meets; ++k) {
            meets = distance(settings.ahead_steps * k / 64.0) < r;
            headed += meets ? 1 : 0;
          }
          if (!meets) continue;
          EXPECT_EQ(kept_ahead.count({a.id, v, b.id, t}), 1u)
              << "step " << step << ": " << a.name << " vertex " << v << " heads into " << b.name << " triangle " << t;
        }
      }
    }
  }
  EXPECT_GT(within_margins, 20u) << "the ball must touch the sheet";
  EXPECT_GT(headed, 20u) << "the ball must head into the sheet";
  // The pairs a fast vertex passes beside or leaves behind are gone.
  EXPECT_LT(candidates_ahead, candidates_radius / 2) << "ahead " << candidates_ahead << ", radius " << candidates_radius;
}

// SensorWorld::setPairAhead puts one body pair on the Ahead bound (what psc::bullet does for a
// pair that runs away): that pair's candidates are exactly those of a world on MotionBound::Ahead,
// every other pair keeps the radius bound's, and once the two bodies' boxes part the pair is back on
// the radius bound. A ball flies through a sheet as above; a second ball rests on the sheet.
TEST(HardConditions, APairOnTheAheadBoundGetsAheadsCandidatesUntilItsBodiesPart) {
  std::vector<Body> bodies = sheetAndBall();
  bodies.push_back(bodies[1]);
  bodies[2].name = "resting ball";
  const TriMesh sheet_rest = bodies[0].mesh, ball_rest = bodies[1].mesh;
  const auto pose = [&](int step, double away) {
    bodies[0].mesh.vertices = sheet_rest.vertices;
    bodies[1].mesh.vertices = ball_rest.vertices;
    for (Vec3& p : bodies[1].mesh.vertices) p += Vec3(-0.6 + 0.04 * step + away, 0.1, 0.8 - 0.1 * step);
    bodies[2].mesh.vertices = ball_rest.vertices;
    for (Vec3& p : bodies[2].mesh.vertices) p += Vec3(1.5, 1.5, 0.41 - 0.005 * step);
  };
  pose(0, 0.0);
  SensorSettings settings;
  settings.motion_bound = MotionBound::Ahead;
  SensorWorld ahead(settings), radius, paired;
  addAll(ahead, bodies);
  for (Body& b : bodies) b.id = radius.addBody(descOf(b));
  for (Body& b : bodies) b.id = paired.addBody(descOf(b));
  const BodyId sheet = bodies[0].id, ball = bodies[1].id, resting = bodies[2].id;
  EXPECT_THROW(paired.setPairAhead(sheet, 99, true), Error);
  EXPECT_THROW(paired.setPairAhead(ball, ball, true), Error);
  using Key = std::tuple<BodyId, Index, BodyId, Index>;
  const auto of = [&](const StepResult& r, bool flying) {
    std::vector<Key> keys;
    for (const CandidatePair& c : r.candidates) {
      const bool pair_is_flying = (c.vertex_body == ball) != (c.triangle_body == ball);
      if (pair_is_flying == flying) keys.push_back({c.vertex_body, c.vertex, c.triangle_body, c.triangle});
    }
    return keys;
  };
  std::size_t flying = 0, rest = 0, fewer = 0;
  bool set = false;
  std::vector<Vec3> prev[3];
  for (int i = 0; i < 3; ++i) prev[i] = bodies[i].mesh.vertices;
  const auto stepAll = [&](int step, double away) {
    pose(step, away);
    for (SensorWorld* w : {&ahead, &radius, &paired})
      for (int i = 0; i < 3; ++i)
        w->setPositions(bodies[i].id, PositionView::of(bodies[i].mesh.vertices), PositionView::of(prev[i]));
  };
  // The worlds read the positions where they are (views): the previous ones change after the steps.
  const auto keep = [&] {
    for (int i = 0; i < 3; ++i) prev[i] = bodies[i].mesh.vertices;
  };
  for (int step = 1; step <= 12; ++step) {
    stepAll(step, 0.0);
    const StepResult& a = ahead.step();
    const std::vector<Key> a_fly = of(a, true);
    const StepResult& r = radius.step();
    const std::vector<Key> r_fly = of(r, true), r_rest = of(r, false);
    const StepResult& p = paired.step();
    EXPECT_TRUE(of(p, false) == r_rest) << "step " << step << ": the other pairs keep the radius bound";
    if (set) {
      EXPECT_TRUE(of(p, true) == a_fly) << "step " << step << ": the pair on the Ahead bound";
      EXPECT_TRUE(paired.pairAhead(sheet, ball)) << "step " << step << ": the bodies still overlap";
      flying += a_fly.size();
      fewer += r_fly.size() - a_fly.size();
    } else {
      EXPECT_TRUE(of(p, true) == r_fly) << "step " << step << ": not yet on the Ahead bound";
      if (!r_fly.empty()) {  // as psc::bullet does on a runaway: from the next step on
        paired.setPairAhead(ball, sheet, true);  // either order
        EXPECT_TRUE(paired.pairAhead(sheet, ball));
        EXPECT_FALSE(paired.pairAhead(sheet, resting));
        set = true;
      }
    }
    rest += r_rest.size();
    keep();
  }
  EXPECT_GT(flying, 20u) << "the ball must meet the sheet";
  EXPECT_GT(rest, 20u) << "the resting ball must touch the sheet";
  EXPECT_GT(fewer, 20u) << "Ahead must differ from Radius on the flying ball";
  // Far away: the boxes part and the pair is released; back on the sheet it has Radius's candidates.
  for (int i = 0; i < 2; ++i) {  // the jump's motion term still reaches; resting far away it does not
    stepAll(12, 50.0);
    paired.step();
    radius.step();
    keep();
  }
  EXPECT_FALSE(paired.pairAhead(sheet, ball));
  stepAll(5, 0.0);  // back in one jump: the radius bound's candidates
  const std::vector<Key> back = of(paired.step(), true);
  EXPECT_FALSE(back.empty());
  EXPECT_TRUE(back == of(radius.step(), true));
}

TEST(HardConditions, StretchedToTwiceItsSizeRepartitionsAndStillFindsContacts) {
  std::vector<Body> bodies(2);
  bodies[0].mesh = makeSphere(1.0, 400);
  bodies[0].name = "balloon";
  bodies[0].particles = 12;
  bodies[1].mesh = makeSphere(0.5, 200);
  bodies[1].name = "probe";
  for (Body& b : bodies) b.margin = 0.02;
  SensorSettings s;
  s.repartition.check_every = 1;
  SensorWorld w(s);
  const TriMesh rest = bodies[0].mesh;
  bodies[1].mesh.translate(Vec3(1.5, 0, 0));  // clear of the balloon at rest
  addAll(w, bodies);
  w.step();
  EXPECT_EQ(w.repartitionCount(bodies[0].id), 0u);
  // Inflate in steps up to twice the size; the probe rests on the growing surface.
  std::size_t contacts = 0;
  for (int k = 1; k <= 5; ++k) {
    const double f = 1.0 + 0.2 * k;
    bodies[0].previous = bodies[0].mesh.vertices;
    bodies[0].mesh = rest;
    bodies[0].mesh.scale(f);
    bodies[1].mesh = makeSphere(0.5, 200).translate(Vec3(f + 0.5, 0, 0));
    w.setPositions(bodies[0].id, PositionView::of(bodies[0].mesh.vertices), PositionView::of(bodies[0].previous));
    contacts += stepAndCheck(w, bodies, 1, "inflating");
  }
  EXPECT_GE(w.repartitionCount(bodies[0].id), 1u) << "twice the size must trigger repartitioning";
  contacts += stepAndCheck(w, bodies, 2, "inflated");
  EXPECT_GT(contacts, 0u);
}

TEST(HardConditions, AReplacedMeshIsCountedAsOneRepartitionWhenItIsPartitioned) {
  // A review's finding (stop 47): replaceMesh raised repartitionCount at once, and the next step,
  // which partitions the new mesh, did not count it in StepStats::repartitions.
  std::vector<Body> bodies = againstSphere(makeSphere(1.0, 200), 0.02);
  SensorWorld w;
  addAll(w, bodies);
  EXPECT_EQ(w.step().stats.repartitions, 0u);
  bodies[0].mesh = makeSphere(1.0, 500);
  w.replaceMesh(bodies[0].id, bodies[0].mesh.triangles, PositionView::of(bodies[0].mesh.vertices));
  EXPECT_EQ(w.repartitionCount(bodies[0].id), 0u) << "not partitioned yet";
  EXPECT_EQ(w.step().stats.repartitions, 1u);
  EXPECT_EQ(w.repartitionCount(bodies[0].id), 1u);
  EXPECT_EQ(w.step().stats.repartitions, 0u);
  EXPECT_EQ(w.repartitionCount(bodies[0].id), 1u);
}

TEST(HardConditions, AGivenParticleCountSurvivesAReplacementByACoarserMesh) {
  // A review's finding (stop 47): a body added with particles = 60 could not be replaced by a mesh
  // of fewer vertices (replaceMesh threw and kept the old mesh). It now gets one particle a vertex,
  // and the 60 again once the mesh is fine enough.
  std::vector<Body> bodies = againstSphere(makeSphere(1.0, 400), 0.02);
  bodies[0].particles = 60;
  SensorWorld w;
  addAll(w, bodies);
  stepAndCheck(w, bodies, 1, "before");
  EXPECT_EQ(w.partition(bodies[0].id).regionCount(), 60u);
  bodies[0].mesh = makeSphere(1.0, 38);
  ASSERT_LT(bodies[0].mesh.vertices.size(), 60u);
  w.replaceMesh(bodies[0].id, bodies[0].mesh.triangles, PositionView::of(bodies[0].mesh.vertices));
  stepAndCheck(w, bodies, 2, "coarse");
  EXPECT_EQ(w.partition(bodies[0].id).regionCount(), bodies[0].mesh.vertices.size());
  bodies[0].mesh = makeSphere(1.0, 400);
  w.replaceMesh(bodies[0].id, bodies[0].mesh.triangles, PositionView::of(bodies[0].mesh.vertices));
  stepAndCheck(w, bodies, 1, "fine again");
  EXPECT_EQ(w.partition(bodies[0].id).regionCount(), 60u);
}

TEST(HardConditions, TheThesissPowerOfTwoCountsWorkInAWorld) {
  // A review's finding (stop 47): with partition.any_count off (the thesis's 2^k), every step threw
  // once a body's budget was not a power of two. Each body now gets the largest power of two within
  // its budget, and a given count must be one.
  SensorSettings s;
  s.partition.any_count = false;
  std::vector<Body> bodies = againstSphere(makeTorus(1.0, 0.3, 800), 0.02);
  std::vector<Body> more = againstSphere(makeSphere(1.0, 300), 0.02);
  more[0].mesh.translate(Vec3(0, 4, 0));
  more[1].mesh.translate(Vec3(0, 4, 0));
  bodies.push_back(more[0]);
  bodies.push_back(more[1]);
  SensorWorld w(s);
  addAll(w, bodies);
  EXPECT_GT(stepAndCheck(w, bodies, 3, "any_count off"), 0u);
  for (const Body& b : bodies) {
    const std::size_t n = w.partition(b.id).regionCount();
    EXPECT_EQ(n & (n - 1), 0u) << b.name << ": " << n << " regions";
  }
  BodyDesc odd = descOf(bodies[0]);
  odd.particles = 6;
  odd.name = "six";
  EXPECT_ERROR_NAMES(w.addBody(odd), "six': particles = 6 is not a power of two");
  odd.particles = 8;
  EXPECT_NO_THROW(w.addBody(odd));
}

TEST(HardConditions, AFloorOfManyRegionsUnderManySmallBodiesLosesNoContact) {
  // A review's finding (stop 47): each body pair read every region of both bodies, so a floor of
  // thousands of regions under a thousand small bodies cost bodies × regions a step. The regions
  // of a body of many (RegionIndex::kIndexedRegions and more) are now found through their boxes
  // sorted along the body's longest axis; the candidates must be those of the full read, every
  // contact within the radius among them (brute force), and two worlds must agree bit for bit.
  std::vector<Body> bodies;
  Body floor;
  floor.mesh = makePatch(8.0, 8.0, 40, 40);  // in the z = 0 plane, about (−4, −4) to (4, 4)
  floor.name = "floor";
  floor.particles = 200;
  floor.margin = 0.02;
  bodies.push_back(floor);
  for (int i = 0; i < 5; ++i)
    for (int j = 0; j < 5; ++j) {
      Body ball;
      ball.mesh = makeSphere(0.3, 60).translate(Vec3(-3.1 + 1.5 * i, -3.1 + 1.5 * j, 0.3 - 0.01 * ((i + j) % 4)));
      ball.name = "ball";
      ball.margin = 0.02;
      bodies.push_back(ball);
    }
  SensorWorld w, twin;
  addAll(w, bodies);
  std::vector<Body> copy = bodies;
  addAll(twin, copy);
  EXPECT_GT(stepAndCheck(w, bodies, 3, "floor"), 0u);
  for (int s = 0; s < 3; ++s) twin.step();
  EXPECT_GE(w.partition(bodies[0].id).regionCount(), 64u) << "the floor's regions must be indexed";
  EXPECT_EQ(w.lastResult().candidates, twin.lastResult().candidates);
  EXPECT_EQ(w.lastResult().stats.region_pairs, twin.lastResult().stats.region_pairs);
}

TEST(HardConditions, ReplacedMeshWithAnotherVertexCountIsRepartitioned) {
  std::vector<Body> bodies = againstSphere(makeSphere(1.0, 200), 0.02);
  SensorWorld w;
  addAll(w, bodies);
  stepAndCheck(w, bodies, 2, "before the rebuild");
  const std::size_t before = w.repartitionCount(bodies[0].id);
  bodies[0].mesh = makeSphere(1.0, 900);  // refined: another vertex count
  w.replaceMesh(bodies[0].id, bodies[0].mesh.triangles, PositionView::of(bodies[0].mesh.vertices));
  EXPECT_GT(stepAndCheck(w, bodies, 2, "after the rebuild"), 0u);
  EXPECT_EQ(w.partition(bodies[0].id).region_of.size(), bodies[0].mesh.vertices.size());
  EXPECT_EQ(w.topology(bodies[0].id).vertexCount(), bodies[0].mesh.vertices.size());
  EXPECT_GT(w.repartitionCount(bodies[0].id), before);
  // A bad rebuild is refused and the body keeps working on the mesh it had.
  std::vector<Triangle> bad = bodies[0].mesh.triangles;
  bad[0][0] = 1u << 30;
  EXPECT_ERROR_NAMES(w.replaceMesh(bodies[0].id, bad, PositionView::of(bodies[0].mesh.vertices)), "out of range");
  EXPECT_GT(stepAndCheck(w, bodies, 1, "after a refused rebuild"), 0u);
}

TEST(HardConditions, TwoHundredBodiesAtLowResolution) {
  // A 10 × 20 grid of small spheres: rows of ten overlapping neighbours, rows well apart.
  std::vector<Body> bodies;
  for (int j = 0; j < 20; ++j)
    for (int i = 0; i < 10; ++i) {
      Body b;
      b.mesh = makeIcosphere(0.5, 1);
      b.mesh.translate(Vec3(0.95 * i, 1.5 * j, 0.0));
      b.margin = 0.05;
      b.name = "s" + std::to_string(i) + "_" + std::to_string(j);
      bodies.push_back(b);
    }
  SensorWorld w;
  addAll(w, bodies);
  EXPECT_GT(stepAndCheck(w, bodies, 2, "200 bodies"), 0u);
  const StepResult& res = w.lastResult();
  EXPECT_EQ(res.stats.bodies, 200u);
  // Conservative flagging may flag near misses (cost, not error), but never bodies out of reach:
  // a region's sphere (particle on the surface, radius at most the diameter 1) stays within 1.5 of
  // its body's centre. Every pair of overlapping neighbours must be flagged.
  std::size_t far_flags = 0;
  std::set<std::pair<BodyId, BodyId>> flagged_bodies;
  for (const FlaggedPair& f : res.flagged) {
    const Vec3 a = bounds(PositionView::of(bodies[f.body_a].mesh.vertices)).center();
    const Vec3 b = bounds(PositionView::of(bodies[f.body_b].mesh.vertices)).center();
    far_flags += (a - b).norm() > 3.0 + 0.1;
    flagged_bodies.insert({f.body_a, f.body_b});
  }
  EXPECT_EQ(far_flags, 0u);
  for (BodyId id = 0; id < 200; ++id)
    if (id % 10 != 9) {
      EXPECT_EQ(flagged_bodies.count({id, id + 1}), 1u) << bodies[id].name;
    }
}

// Everything a run leaves behind that must be reproducible, hashed (FNV-1a).
struct Hasher {
  std::uint64_t h = 1469598103934665603ull;
  void bytes(const void* p, std::size_t n) {
    for (std::size_t i = 0; i < n; ++i) h = (h ^ static_cast<const unsigned char*>(p)[i]) * 1099511628211ull;
  }
  template <class T>
  void value(const T& v) {
    bytes(&v, sizeof v);
  }
};

std::uint64_t runScene(SensorWorld& w, std::vector<Body>& bodies) {
  addAll(w, bodies);
  Hasher hash;
  const std::vector<Vec3> rest = bodies[1].mesh.vertices;
  for (int s = 0; s < 6; ++s) {
    bodies[1].previous = bodies[1].mesh.vertices;
    for (std::size_t v = 0; v < rest.size(); ++v)  // the torus sways and deforms
      bodies[1].mesh.vertices[v] = rest[v] + Vec3(-0.02 * s, 0.01 * std::sin(3.0 * rest[v].z() + s), 0.0);
    w.setPositions(bodies[1].id, PositionView::of(bodies[1].mesh.vertices), PositionView::of(bodies[1].previous));
    const StepResult& res = w.step();
    hash.value(res.stats.flagged_pairs);
    hash.value(res.stats.candidate_pairs);
    hash.value(res.stats.rounds);
    for (const auto& [ba, ra, bb, rb] : flagsOf(res, bodies)) {  // field by field: tuples have padding
      hash.value(ba);
      hash.value(ra);
      hash.value(bb);
      hash.value(rb);
    }
  }
  for (const Body& b : bodies)
    for (const ParticleState& p : w.particles())
      if (p.body == b.id) {
        hash.value(p.region);
        hash.value(p.vertex);
        const Vec3 x = b.mesh.vertices[p.vertex];
        hash.bytes(x.data(), 3 * sizeof(double));
      }
  return hash.h;
}

TEST(HardConditions, DeterministicAcrossRunsAndAfterAnUnrelatedBodyCameAndWent) {
  std::vector<Body> first = touchingScene(), second = touchingScene(), third = touchingScene();
  SensorWorld w1, w2, w3;
  const std::uint64_t h1 = runScene(w1, first);
  const std::uint64_t h2 = runScene(w2, second);
  // w3 has held, stepped and dropped another body before the scene arrives: nothing of it stays.
  Body unrelated;
  unrelated.mesh = makeTorus(2.0, 0.5, 600).translate(Vec3(-1, 0.5, 0));
  unrelated.margin = 0.1;
  unrelated.name = "unrelated";
  std::vector<Body> others{unrelated};
  addAll(w3, others);
  Body stray = touchingScene()[0];
  stray.id = w3.addBody(descOf(stray));
  for (int s = 0; s < 3; ++s) w3.step();
  w3.removeBody(others[0].id);
  w3.removeBody(stray.id);
  const std::uint64_t h3 = runScene(w3, third);
  EXPECT_EQ(h1, h2);
  EXPECT_EQ(h1, h3);
  EXPECT_NE(third[0].id, first[0].id) << "ids are never reused, so the comparison is by body order";
}

TEST(HardConditions, TwoWorldsInTwoThreadsMatchSequentialRuns) {
  std::vector<Body> s1 = touchingScene(), s2 = touchingScene();
  s2[0].mesh.translate(Vec3(0.1, 0, 0));  // a different scene in the second world
  std::vector<Body> p1 = s1, p2 = s2;
  SensorWorld a, b;
  const std::uint64_t seq1 = runScene(a, s1);
  const std::uint64_t seq2 = runScene(b, s2);
  std::uint64_t par1 = 0, par2 = 0;
  SensorWorld c, d;
  std::thread t1([&] { par1 = runScene(c, p1); });
  std::thread t2([&] { par2 = runScene(d, p2); });
  t1.join();
  t2.join();
  EXPECT_EQ(par1, seq1);
  EXPECT_EQ(par2, seq2);
  EXPECT_NE(seq1, seq2) << "the two scenes differ, so equal hashes are not a coincidence";
}

}  // namespace
}  // namespace psc
