// libFuzzer target: arbitrary bytes read as a small mesh go through validation, partitioning and a
// few SensorWorld steps (two or three bodies, deformation, a mesh rebuild, a removal). Bad input
// must end in psc::Error; anything else that escapes (a crash, UB, another exception, a hang) is a
// bug. Beyond "no crash", the documented contracts are checked: partition invariants, and in the
// default flagging mode every vertex-triangle pair within the contact radius is a candidate pair.
//
// Input layout (all sizes bounded so one input runs in milliseconds):
//   byte 0  flags: 1 raw doubles | 2 Flagging::Sensors | 4 convex parts given (no HACD) |
//           8 thesis split rule | 16 previous positions (motion term) | 32 third body |
//           64 replaceMesh | 128 four-direction area estimator
//   byte 1  vertex count n (0..64)           byte 2  particle override (0 = auto) / LBG count
//   byte 3  margin (odd: self-collision of the fuzzed body)   byte 4, 5  offset of the copy (x, y)
//   byte 6  scale exponent                   byte 7  velocity for the motion term (odd: swept bound)
//   then    n×3 coordinates: int8/8 each, or little-endian doubles with flag 1
//   then    triangles, 3 index bytes each (index = byte mod (n+1), so n itself is out of range)
#include "psc/error.h"
#include "psc/partition.h"
#include "psc/shapes.h"
#include "psc/testkit/reference.h"
#include "psc/world.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <memory>
#include <set>
#include <tuple>
#include <vector>

namespace {

using namespace psc;

constexpr std::size_t kMaxVertices = 64;
constexpr std::size_t kMaxTriangles = 128;

// A broken contract is a finding: abort so libFuzzer keeps the input.
void require(bool ok, const char* what) {
  if (ok) return;
  std::fprintf(stderr, "psc fuzz: contract broken: %s\n", what);
  std::abort();
}

struct Reader {
  const std::uint8_t* p;
  std::size_t left;
  std::uint8_t byte() {
    if (left == 0) return 0;
    --left;
    return *p++;
  }
  double rawDouble() {
    std::uint8_t b[8] = {};
    for (std::uint8_t& x : b) x = byte();
    double d;
    std::memcpy(&d, b, sizeof d);
    return d;
  }
};

struct Input {
  std::uint8_t flags = 0;
  std::size_t particles = 0;
  double margin = 0.0;
  Vec3 offset = Vec3::Zero();
  double speed = 0.0;
  bool self_collision = false;  ///< the fuzzed body collides with itself (default flagging only)
  bool swept = false;           ///< MotionBound::Swept (default flagging only)
  TriMesh mesh;
};

Input decode(const std::uint8_t* data, std::size_t size) {
  Reader r{data, size};
  Input in;
  in.flags = r.byte();
  const std::size_t n = r.byte() % (kMaxVertices + 1);
  in.particles = r.byte() % 9;
  const std::uint8_t margin_byte = r.byte();
  in.margin = margin_byte / 256.0;
  in.self_collision = (margin_byte & 1) != 0;
  const double ox = static_cast<std::int8_t>(r.byte()) / 16.0;
  const double oy = static_cast<std::int8_t>(r.byte()) / 16.0;
  const int exponent = static_cast<std::int8_t>(r.byte()) / 4;
  const std::uint8_t speed_byte = r.byte();
  in.speed = speed_byte / 64.0;
  in.swept = (speed_byte & 1) != 0;
  const double scale = std::ldexp(1.0, exponent);
  in.offset = Vec3(ox, oy, 0.0) * scale;
  in.margin *= scale;
  in.speed *= scale;
  in.mesh.vertices.resize(n);
  for (Vec3& v : in.mesh.vertices)
    for (int k = 0; k < 3; ++k)
      v[k] = (in.flags & 1) ? r.rawDouble() : scale * static_cast<std::int8_t>(r.byte()) / 8.0;
  while (r.left >= 3 && in.mesh.triangles.size() < kMaxTriangles) {
    Triangle t{};
    for (Index& i : t) i = static_cast<Index>(r.byte() % (n + 1));
    in.mesh.triangles.push_back(t);
  }
  return in;
}

void checkPartition(const MeshTopology& topo, const Partition& p, std::size_t count, bool connect) {
  require(p.region_of.size() == topo.vertexCount(), "one region label per vertex");
  require(p.regionCount() == count && p.code_vectors.size() == count, "exactly the asked number of regions");
  std::vector<std::size_t> used_in(count, 0);
  std::set<Index> pieces;
  for (Index v = 0; v < topo.vertexCount(); ++v) {
    require(p.region_of[v] < count, "region label in range");
    if (topo.vertexTriangles(v).empty()) continue;
    ++used_in[p.region_of[v]];
    pieces.insert(topo.componentOf()[v]);
  }
  for (std::size_t r = 0; r < count; ++r) {
    require(used_in[r] > 0, "every region holds a vertex of a triangle");
    const Index s = p.seed_vertex[r];
    require(s < topo.vertexCount() && p.region_of[s] == r && !topo.vertexTriangles(s).empty(),
            "the seed vertex lies in its region and in a triangle");
  }
  if (connect && count >= pieces.size()) require(p.disconnected_regions == 0, "connected regions when possible");
}

// A scene body: the mesh whose memory the views point into.
struct Held {
  BodyId id = kInvalidBody;
  double margin = 0.0;
  TriMesh mesh;
  std::vector<Vec3> previous;  // empty: no previous-position view
};

BodyId add(SensorWorld& world, Held& h, const char* name, const std::shared_ptr<const ConvexParts>& parts) {
  BodyDesc d;
  d.triangles = h.mesh.triangles;
  d.positions = PositionView::of(h.mesh.vertices);
  if (!h.previous.empty()) d.previous = PositionView::of(h.previous);
  d.margin = h.margin;
  d.parts = parts;
  d.name = name;
  h.id = world.addBody(d);
  return h.id;
}

// The conservative mode's promise: every vertex-triangle pair of two bodies closer than the
// contact radius margin_A + margin_B + motion_factor·|x − x_prev| is a candidate pair. Half the
// radius leaves room for rounding; triangles of (nearly) zero area have no reliable distance, and
// neither has a pair whose coordinates reach 1e8 times the radius: the reference distance's
// rounding then exceeds the radius itself (a vertex at the origin against a sliver with corners
// at 1e23 came out at 6e-28 from it, where it is 1e5 away).
void checkCoverage(const SensorWorld& world, const std::vector<Held>& bodies) {
  std::set<std::tuple<BodyId, Index, BodyId, Index>> cand;
  for (const CandidatePair& c : world.lastResult().candidates)
    cand.insert({c.vertex_body, c.vertex, c.triangle_body, c.triangle});
  const double factor = world.settings().motion_factor;
  for (const Held& a : bodies)
    for (const Held& b : bodies) {
      if (a.id == b.id) continue;
      const auto radius = [&](Index v) {
        const double motion = a.previous.empty() ? 0.0 : (a.mesh.vertices[v] - a.previous[v]).norm();
        return 0.5 * (a.margin + b.margin + factor * motion);
      };
      const auto unreliable = [&](Index v, Index t) {
        const Triangle& tri = b.mesh.triangles[t];
        const Vec3 &p = b.mesh.vertices[tri[0]], &q = b.mesh.vertices[tri[1]], &r = b.mesh.vertices[tri[2]];
        const double longest = std::max({(q - p).norm(), (r - q).norm(), (p - r).norm()});
        const double far = std::max({a.mesh.vertices[v].cwiseAbs().maxCoeff(), p.cwiseAbs().maxCoeff(),
                                     q.cwiseAbs().maxCoeff(), r.cwiseAbs().maxCoeff()});
        return !((q - p).cross(r - p).norm() > 1e-6 * longest * longest) || !(far < 1e8 * radius(v));
      };
      testkit::forEachContact(a.mesh.vertices, b.mesh.vertices, b.mesh.triangles, radius, unreliable,
                              [&](Index v, Index t, double distance) {
                                if (cand.count({a.id, v, b.id, t}) == 1) return;
                                std::fprintf(stderr,
                                             "psc fuzz: vertex %u of body %u at distance %g of triangle %u of body "
                                             "%u (radius %g)\n",
                                             v, a.id, distance, t, b.id, radius(v));
                                require(false, "a vertex-triangle pair within the contact radius is a candidate");
                              });
    }
}

// Self pairs never hold a triangle with its own vertex (CollideVF_SS would accept it at distance 0).
void checkSelfPairs(const SensorWorld& world, const std::vector<Held>& bodies) {
  for (const CandidatePair& c : world.lastResult().candidates) {
    if (c.vertex_body != c.triangle_body) continue;
    require(world.selfCollision(c.vertex_body), "self pairs only for bodies with self-collision");
    for (const Held& h : bodies)
      if (h.id == c.vertex_body) {
        const Triangle& t = h.mesh.triangles.at(c.triangle);
        require(t[0] != c.vertex && t[1] != c.vertex && t[2] != c.vertex, "no self pair of a vertex and its own triangle");
      }
  }
}

void runWorld(const Input& in) {
  SensorSettings s;
  s.flagging = (in.flags & 2) ? Flagging::Sensors : Flagging::SensorsAndBounds;
  if (in.swept && s.flagging == Flagging::SensorsAndBounds) s.motion_bound = MotionBound::Swept;
  s.partition.split = (in.flags & 8) ? SplitRule::Thesis : SplitRule::Principal;
  s.repartition.estimator = (in.flags & 128) ? AreaEstimator::FourDirectionWalk : AreaEstimator::TrueArea;
  s.repartition.check_every = 1;
  s.max_rounds = 16;
  SensorWorld world(s);
  // The coverage contract below is the radius bound's; the swept bound's is a unit test's.
  const bool conservative = s.flagging == Flagging::SensorsAndBounds && s.motion_bound == MotionBound::Radius;

  std::shared_ptr<const ConvexParts> parts;
  if (in.flags & 4) {
    // One part holding every vertex: the budget without HACD.
    auto p = std::make_shared<ConvexParts>();
    p->part_of.assign(in.mesh.vertices.size(), 0);
    ConvexPart part;
    part.radius = 1.0;
    part.vertex_count = in.mesh.vertices.size();
    p->parts.push_back(part);
    parts = p;
  }

  std::vector<Held> bodies(2);
  bodies[0].mesh = in.mesh;
  bodies[0].margin = in.margin;
  bodies[1].mesh = in.mesh;
  bodies[1].mesh.rotate(Vec3(0.3, 0.2, 1.0), 0.5).translate(in.offset);
  bodies[1].margin = in.margin;
  if (in.flags & 16)
    for (Held& h : bodies) {
      h.previous = h.mesh.vertices;
      for (Vec3& p : h.previous) p.x() -= in.speed;
    }
  add(world, bodies[0], "fuzzed", parts);
  add(world, bodies[1], "copy", parts);
  if (in.self_collision && s.flagging == Flagging::SensorsAndBounds) world.setSelfCollision(bodies[0].id, true);
  if (in.flags & 32) {
    Held ball;
    ball.mesh = makeIcosphere(0.5, 0);
    ball.margin = 0.05;
    bodies.push_back(ball);
    add(world, bodies.back(), "ball", nullptr);
  }
  // Views point into `bodies`, which no longer reallocates.

  world.step();
  if (conservative) checkCoverage(world, bodies);
  checkSelfPairs(world, bodies);

  // Stretch the fuzzed body to twice its size: a repartition check runs every step.
  Held& a = bodies[0];
  std::vector<Vec3> before = a.mesh.vertices;
  Vec3 centre = Vec3::Zero();
  for (const Vec3& p : before) centre += p;
  centre /= static_cast<double>(std::max<std::size_t>(1, before.size()));
  for (Vec3& p : a.mesh.vertices) p = centre + 2.0 * (p - centre);
  a.previous = before;
  world.setPositions(a.id, PositionView::of(a.mesh.vertices), PositionView::of(a.previous));
  world.step();
  if (conservative) checkCoverage(world, bodies);
  checkSelfPairs(world, bodies);

  if (in.flags & 64) {
    // A rebuilt mesh with one more vertex (a fan triangle on the first edge).
    const Triangle t0 = a.mesh.triangles[0];
    a.mesh.vertices.push_back(a.mesh.vertices[t0[0]] + Vec3(0.0, 0.0, 0.25));
    a.mesh.triangles.push_back({t0[0], t0[1], static_cast<Index>(a.mesh.vertices.size() - 1)});
    a.previous.clear();
    world.replaceMesh(a.id, a.mesh.triangles, PositionView::of(a.mesh.vertices));
    world.step();
    if (conservative) checkCoverage(world, bodies);
    checkSelfPairs(world, bodies);
  }

  world.removeBody(bodies[1].id);
  bodies.erase(bodies.begin() + 1);
  world.step();
  if (conservative) checkCoverage(world, bodies);
  checkSelfPairs(world, bodies);
}

void runPartition(const Input& in) {
  const MeshTopology topo(in.mesh.triangles, in.mesh.vertices.size());
  const PositionView view = PositionView::of(in.mesh.vertices);
  const MeshReport report = validate(topo, view, "fuzzed");
  require(report.degenerate_triangles <= topo.triangleCount(), "degenerate count bounded");
  require(report.isolated_vertices < topo.vertexCount(), "a vertex of a triangle is not isolated");
  std::size_t used = 0;
  for (Index v = 0; v < topo.vertexCount(); ++v) used += topo.vertexTriangles(v).empty() ? 0 : 1;
  PartitionSettings ps;
  ps.split = (in.flags & 8) ? SplitRule::Thesis : SplitRule::Principal;
  ps.connect_regions = (in.flags & 2) == 0;
  const std::size_t count = 1 + in.particles % used;
  const Partition p = partitionLBG(topo, view, count, ps);
  checkPartition(topo, p, count, ps.connect_regions);
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const Input in = decode(data, size);
  try {
    runPartition(in);
  } catch (const psc::Error& e) {
    require(std::strlen(e.what()) > 0, "an error says what is wrong");
  }
  try {
    runWorld(in);
  } catch (const psc::Error& e) {
    require(std::strlen(e.what()) > 0, "an error says what is wrong");
  }
  return 0;
}
