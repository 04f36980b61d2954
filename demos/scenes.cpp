#include "scenes.h"

#include "mesh_file.h"
#include "psc/error.h"

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <limits>
#include <map>
#include <numeric>
#include <sstream>

namespace psc::demo {
namespace {

constexpr double kPi = 3.14159265358979323846;
constexpr double kGravity = 9.81;
/// Piles step at 120 Hz. Bullet's soft-soft response (PSolve_SContacts) pushes a node out to
/// margin + 2·|Δx|, so a node that moved far is pushed further and moves faster still: at 60 Hz
/// dense piles of 2,000-vertex tori diverged (node speeds > 1,000 units/s, then NaN) in both
/// pipelines, and even without divergence nodes jittered at 30-50 units/s; at 120 Hz the fastest
/// node settles near 10 units/s.
constexpr double kPileStep = 1.0 / 120.0;

/// splitmix64: the same numbers on every platform and standard library (std::uniform_*
/// distributions are implementation-defined), so a seed names one scene everywhere.
class Random {
 public:
  explicit Random(std::uint64_t seed) : state_(seed * 0x9E3779B97F4A7C15ull + 0x632BE59BD9B4E019ull) {}
  double uniform(double lo, double hi) { return lo + (hi - lo) * unit(); }
  Vec3 unitVector() {
    const double z = uniform(-1.0, 1.0), phi = uniform(0.0, 2.0 * kPi), s = std::sqrt(std::max(0.0, 1.0 - z * z));
    return {s * std::cos(phi), s * std::sin(phi), z};
  }

 private:
  double unit() {
    std::uint64_t z = (state_ += 0x9E3779B97F4A7C15ull);
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
    z ^= z >> 31;
    return static_cast<double>(z >> 11) * (1.0 / 9007199254740992.0);
  }
  std::uint64_t state_;
};

Error badParam(const std::string& what) { return Error(ErrorCode::InvalidArgument, what); }

/// Closed bodies hold their shape with bending links (2-ring) and volume conservation (kVC with
/// the rest volume): a 2 kg unit ball resting on the ground keeps ~85% of its height. Measured
/// alternatives: kVC alone let balls flatten to 60%; gas pressure (kPR, force ∝ 1/V) blew piles
/// apart once a squeezed tube's volume neared zero. No shape matching: a frame pose moves nodes
/// after the face-tree refit and would break the exact split of Bullet's collision time
/// (bullet_scene.h).
SoftBodySpec ball(std::string name, TriMesh mesh, double mass = 1.0) {
  SoftBodySpec b;
  b.name = std::move(name);
  b.mesh = std::move(mesh);
  b.mass = mass;
  b.stiffness = 0.9;
  b.volume_conservation = 20.0;
  b.bending_distance = 2;
  return b;
}

SoftBodySpec cloth(std::string name, TriMesh mesh, double mass = 0.5) {
  SoftBodySpec b;
  b.name = std::move(name);
  b.mesh = std::move(mesh);
  b.mass = mass;
  b.stiffness = 0.8;
  b.bending_distance = 2;
  b.damping = 0.02;
  return b;
}

/// A torus with its axis vertical (makeTorus winds around z).
TriMesh flatTorus(double major, double minor, std::size_t n) {
  TriMesh t = makeTorus(major, minor, n);
  t.rotate(Vec3::UnitX(), -kPi / 2);
  return t;
}

/// A cloth patch in the horizontal plane with about n vertices.
TriMesh flatPatch(double size, std::size_t n) {
  const auto side = static_cast<std::size_t>(std::max(2.0, std::round(std::sqrt(static_cast<double>(n)))));
  TriMesh p = makePatch(size, size, side, side);
  p.rotate(Vec3::UnitX(), -kPi / 2);
  return p;
}

struct Box {
  Vec3 lo, hi;
};
Box boundsOf(const TriMesh& m) {
  Box b{m.vertices.at(0), m.vertices.at(0)};
  for (const Vec3& p : m.vertices) {
    b.lo = b.lo.cwiseMin(p);
    b.hi = b.hi.cwiseMax(p);
  }
  return b;
}

/// Keeps the largest piece of triangles connected through shared edges. Bullet's VF_SS setup
/// cannot build a tree over several pieces (see bullet_vf_setup.h). Returns the pieces dropped.
std::size_t keepLargestPiece(TriMesh& mesh) {
  const std::size_t nf = mesh.triangles.size();
  std::vector<std::size_t> root(nf);
  std::iota(root.begin(), root.end(), 0);
  const auto find = [&](std::size_t x) {
    while (root[x] != x) x = root[x] = root[root[x]];
    return x;
  };
  std::map<std::pair<Index, Index>, std::size_t> first_with_edge;
  for (std::size_t f = 0; f < nf; ++f)
    for (std::size_t k = 0; k < 3; ++k) {
      const auto e = std::minmax(mesh.triangles[f][k], mesh.triangles[f][(k + 1) % 3]);
      const auto [it, inserted] = first_with_edge.emplace(e, f);
      if (!inserted) root[find(f)] = find(it->second);
    }
  std::map<std::size_t, std::size_t> size;
  for (std::size_t f = 0; f < nf; ++f) ++size[find(f)];
  if (size.size() <= 1) return 0;
  std::size_t best = size.begin()->first;
  for (const auto& [r, n] : size)
    if (n > size[best]) best = r;
  TriMesh kept;
  std::vector<Index> remap(mesh.vertices.size(), kInvalidIndex);
  for (std::size_t f = 0; f < nf; ++f) {
    if (find(f) != best) continue;
    Triangle t = mesh.triangles[f];
    for (Index& v : t) {
      if (remap[v] == kInvalidIndex) {
        remap[v] = static_cast<Index>(kept.vertices.size());
        kept.vertices.push_back(mesh.vertices[v]);
      }
      v = remap[v];
    }
    kept.triangles.push_back(t);
  }
  mesh = std::move(kept);
  return size.size() - 1;
}

StaticBoxSpec ground(double half = 8.0) { return {Vec3(0, -0.5, 0), Vec3(half, 0.5, half)}; }

std::size_t bodyCount(const SceneParams& p, const SceneInfo& info) {
  const std::size_t k = p.bodies ? p.bodies : info.default_bodies;
  if (k < 1) throw badParam("scene '" + info.name + "': needs at least 1 body");
  return k;
}

Scene headOn(const SceneParams& p) {
  Scene s;
  s.title = "two equal soft spheres meeting head-on";
  s.bodies.push_back(ball("sphere_left", makeSphere(1.0, p.resolution).translate({-1.5, 0, 0})));
  s.bodies.push_back(ball("sphere_right", makeSphere(1.0, p.resolution).translate({1.5, 0, 0})));
  s.bodies[0].velocity = {3, 0, 0};
  s.bodies[1].velocity = {-3, 0, 0};
  return s;
}

Scene row(const SceneParams& p, bool mixed) {
  Scene s;
  const double rm = mixed ? 0.5 : 1.0;
  const double x = mixed ? 2.0 : 2.5;
  s.title = mixed ? "three spheres in a row, diameters D, D/2, D" : "three equal spheres in a row";
  s.bodies.push_back(ball("left", makeSphere(1.0, p.resolution).translate({-x, 0, 0})));
  s.bodies.push_back(ball("middle", makeSphere(rm, p.resolution), mixed ? 0.5 : 1.0));
  s.bodies.push_back(ball("right", makeSphere(1.0, p.resolution).translate({x, 0, 0})));
  s.bodies[0].velocity = {3, 0, 0};
  s.bodies[2].velocity = {-3, 0, 0};
  return s;
}

Scene interlock(const SceneParams& p) {
  // Two U shapes in perpendicular planes, hooked like chain links and pushed together: the bend of
  // each enters the other's opening, so the contact sits inside both concave bodies.
  Scene s;
  s.title = "two U shapes in perpendicular planes hooking into each other";
  const double width = 1.2, arm = 1.5, tube = 0.2, gap = 0.4;
  TriMesh lower = makeUShape(width, arm, tube, p.resolution);
  Box b = boundsOf(lower);
  lower.translate({-0.5 * (b.lo.x() + b.hi.x()), -b.lo.y(), -0.5 * (b.lo.z() + b.hi.z())});
  TriMesh upper = makeUShape(width, arm, tube, p.resolution);
  upper.rotate(Vec3::UnitZ(), kPi).rotate(Vec3::UnitY(), kPi / 2);
  b = boundsOf(upper);
  // The upper bend's underside starts `gap` above the lower bend's upper side (both 2·tube thick).
  upper.translate({-0.5 * (b.lo.x() + b.hi.x()), 2 * tube + gap + 2 * tube - b.hi.y(), -0.5 * (b.lo.z() + b.hi.z())});
  s.bodies.push_back(ball("u_lower", std::move(lower)));
  s.bodies.push_back(ball("u_upper", std::move(upper)));
  s.bodies[0].velocity = {0, 1.5, 0};
  s.bodies[1].velocity = {0, -1.5, 0};
  return s;
}

/// Drops a mesh into a pile: moved so that its box sits `gap` above every earlier body whose box
/// it overlaps in x and z (and above `floor`). Piles so built start with no body touching
/// another, whatever the orientations: the benchmark measures the pipelines, not a setup that
/// begins interpenetrated.
TriMesh& stackOnto(const std::vector<SoftBodySpec>& placed, TriMesh& mesh, double floor, double gap) {
  const Box b = boundsOf(mesh);
  double bottom = floor;
  for (const SoftBodySpec& other : placed) {
    const Box o = boundsOf(other.mesh);
    const bool overlap_xz = b.lo.x() < o.hi.x() + gap && o.lo.x() < b.hi.x() + gap && b.lo.z() < o.hi.z() + gap &&
                            o.lo.z() < b.hi.z() + gap;
    if (overlap_xz) bottom = std::max(bottom, o.hi.y() + gap);
  }
  return mesh.translate({0, bottom - b.lo.y(), 0});
}

Scene toriPile(const SceneParams& p, std::size_t k) {
  // Two staggered columns, so each torus lands half on the one below and the pile interlocks.
  Scene s;
  s.title = std::to_string(k) + " soft tori dropped into a pile";
  s.gravity = {0, -kGravity, 0};
  s.dt = kPileStep;
  s.statics.push_back(ground());
  Random rng(p.seed);
  for (std::size_t i = 0; i < k; ++i) {
    TriMesh t = flatTorus(0.8, 0.3, p.resolution);
    t.rotate(Vec3::UnitY(), rng.uniform(0, 2 * kPi));
    t.rotate(Vec3(rng.uniform(-1, 1), 0, rng.uniform(-1, 1)), rng.uniform(0, 0.35));
    t.translate({(i % 2 ? 0.5 : -0.5) + rng.uniform(-0.15, 0.15), 0, rng.uniform(-0.3, 0.3)});
    stackOnto(s.bodies, t, 0.15, 0.12);
    s.bodies.push_back(ball("torus_" + std::to_string(i), std::move(t)));
  }
  return s;
}

Scene mixedPile(const SceneParams& p, std::size_t k) {
  Scene s;
  s.title = std::to_string(k) + " spheres, tori and cloth patches dropped into a static box";
  s.gravity = {0, -kGravity, 0};
  s.dt = kPileStep;
  const double inner = 2.0;  // half width inside the walls
  s.statics.push_back(ground(inner + 1.0));
  s.statics.push_back({Vec3(-inner - 0.25, 3.5, 0), Vec3(0.25, 4.0, inner + 0.5)});
  s.statics.push_back({Vec3(inner + 0.25, 3.5, 0), Vec3(0.25, 4.0, inner + 0.5)});
  s.statics.push_back({Vec3(0, 3.5, -inner - 0.25), Vec3(inner + 0.5, 4.0, 0.25)});
  s.statics.push_back({Vec3(0, 3.5, inner + 0.25), Vec3(inner + 0.5, 4.0, 0.25)});
  Random rng(p.seed);
  for (std::size_t i = 0; i < k; ++i) {
    // Four columns, shifted a little each layer so that bodies land across each other.
    const double cx = (i % 2 ? 0.8 : -0.8) + rng.uniform(-0.3, 0.3);
    const double cz = ((i / 2) % 2 ? 0.8 : -0.8) + rng.uniform(-0.3, 0.3);
    const std::string id = std::to_string(i);
    TriMesh m;
    switch (i % 3) {
      case 0:
        m = makeSphere(0.5, p.resolution);
        break;
      case 1:
        m = flatTorus(0.55, 0.2, p.resolution);
        m.rotate(Vec3(rng.uniform(-1, 1), 0, rng.uniform(-1, 1)), rng.uniform(0, 0.6));
        break;
      default:
        m = flatPatch(1.3, p.resolution);
        m.rotate(Vec3::UnitY(), rng.uniform(0, kPi / 2));
    }
    m.translate({cx, 0, cz});
    stackOnto(s.bodies, m, 0.15, 0.12);
    if (i % 3 == 2)
      s.bodies.push_back(cloth("cloth_" + id, std::move(m), 0.3));
    else
      s.bodies.push_back(ball((i % 3 ? "torus_" : "sphere_") + id, std::move(m)));
  }
  return s;
}

Scene clothBall(const SceneParams& p) {
  Scene s;
  s.title = "a cloth patch falling onto a soft ball";
  s.gravity = {0, -kGravity, 0};
  s.statics.push_back(ground());
  s.bodies.push_back(ball("ball", makeSphere(1.0, p.resolution).translate({0, 1.06, 0}), 2.0));
  s.bodies.push_back(cloth("cloth", flatPatch(3.0, p.resolution).translate({0.1, 2.6, -0.05})));
  return s;
}

Scene fastImpact(const SceneParams& p) {
  // 30 units/s at 60 Hz: the small sphere moves half its diameter per step, more than its regions
  // span, and Bullet's motion term (2·|Δx| = 1 unit) dwarfs the margins.
  Scene s;
  s.title = "a small sphere hitting a big one at 30 units/s (0.5 units per step)";
  s.bodies.push_back(ball("target", makeSphere(1.0, p.resolution), 2.0));
  s.bodies.push_back(ball("bullet", makeSphere(0.5, p.resolution).translate({-3.5, 0.2, 0}), 0.5));
  s.bodies[1].velocity = {30, 0, 0};
  return s;
}

Scene projectile(const SceneParams& p) {
  // A 0.25-radius sphere at 30 units/s moves 0.5 units per step at 60 Hz, its own diameter: a node
  // can pass the block's face between two steps without ever being within a margin of it.
  Scene s;
  s.title = "a small soft sphere at 30 units/s into a large soft block (one diameter per step)";
  s.bodies.push_back(ball("block", makeBox({0.5, 1.5, 1.5}, p.resolution), 6.0));
  s.bodies.push_back(ball("projectile", makeSphere(0.25, p.resolution).translate({-3.0, 0.1, -0.05}), 0.2));
  s.bodies[1].velocity = {30, 0, 0};
  return s;
}

/// The vertices of a patch at the four corners of its bounding box in x and z.
std::vector<Index> cornersOf(const TriMesh& m) {
  const Box b = boundsOf(m);
  std::vector<Index> corners;
  for (const double x : {b.lo.x(), b.hi.x()})
    for (const double z : {b.lo.z(), b.hi.z()}) {
      Index best = 0;
      double best_d = std::numeric_limits<double>::infinity();
      for (std::size_t v = 0; v < m.vertices.size(); ++v) {
        const double d = std::hypot(m.vertices[v].x() - x, m.vertices[v].z() - z);
        if (d < best_d) best_d = d, best = static_cast<Index>(v);
      }
      corners.push_back(best);
    }
  return corners;
}

Scene fastCloth(const SceneParams& p) {
  // 20 units/s at 60 Hz: the ball moves 0.33 units per step through a cloth of thickness 0 (only
  // the margins), so a node can cross the cloth between two steps.
  Scene s;
  s.title = "a soft ball at 20 units/s into a cloth pinned at its corners";
  s.gravity = {0, -kGravity, 0};
  s.bodies.push_back(cloth("cloth", flatPatch(3.0, p.resolution)));
  s.bodies[0].pinned = cornersOf(s.bodies[0].mesh);
  s.bodies.push_back(ball("ball", makeSphere(0.5, p.resolution).translate({0.05, 2.0, -0.1}), 1.0));
  s.bodies[1].velocity = {0, -20, 0};
  return s;
}

Scene clothFold(const SceneParams& p) {
  // The cloth lands across a thin bar a little off its middle: the halves swing down on both sides
  // and meet under the bar, the longer half drags the cloth off, and it lands folded on the ground.
  // Without self-collision the halves pass through each other where they meet.
  Scene s;
  s.title = "a cloth dropped across a thin bar: its halves swing together and it falls folded";
  s.gravity = {0, -kGravity, 0};
  s.dt = kPileStep;
  s.statics.push_back(ground());
  s.statics.push_back({Vec3(0, 1.6, 0), Vec3(0.04, 0.04, 2.5)});
  s.bodies.push_back(cloth("cloth", flatPatch(3.0, p.resolution).translate({0.35, 1.8, 0.02})));
  return s;
}

/// A closed tube of radius r around the helix (R cos θ, pitch·θ/2π, R sin θ), θ in [0, 2π·turns],
/// with about n vertices: rings of m vertices about as far apart along the tube as around it, and a
/// fan closing each end. Rings are placed in the frame (radial, radial × tangent) of the helix, so
/// every triangle is wound outward (positive volume).
TriMesh helixTube(double R, double pitch, double turns, double r, std::size_t n) {
  const double rise = pitch / (2 * kPi);
  const double length = 2 * kPi * turns * std::sqrt(R * R + rise * rise);
  const auto m = static_cast<std::size_t>(
      std::max(6.0, std::round(std::sqrt(static_cast<double>(n) * 2 * kPi * r / length))));
  const std::size_t rings = std::max<std::size_t>(2, (std::max<std::size_t>(n, 2 * m + 2) - 2) / m);
  TriMesh t;
  for (std::size_t i = 0; i < rings; ++i) {
    const double th = 2 * kPi * turns * static_cast<double>(i) / static_cast<double>(rings - 1);
    const Vec3 c(R * std::cos(th), rise * th, R * std::sin(th));
    const Vec3 tangent = Vec3(-R * std::sin(th), rise, R * std::cos(th)).normalized();
    const Vec3 radial(std::cos(th), 0, std::sin(th));
    const Vec3 side = radial.cross(tangent);
    for (std::size_t j = 0; j < m; ++j) {
      const double phi = 2 * kPi * static_cast<double>(j) / static_cast<double>(m);
      t.vertices.push_back(c + r * (std::cos(phi) * radial + std::sin(phi) * side));
    }
  }
  const auto at = [&](std::size_t i, std::size_t j) { return static_cast<Index>(i * m + j % m); };
  for (std::size_t i = 0; i + 1 < rings; ++i)
    for (std::size_t j = 0; j < m; ++j) {
      t.triangles.push_back({at(i, j), at(i + 1, j), at(i + 1, j + 1)});
      t.triangles.push_back({at(i, j), at(i + 1, j + 1), at(i, j + 1)});
    }
  // End caps: a centre vertex each, fans facing back along the tube at the start, forward at the end.
  const auto cap = [&](std::size_t ring, bool start) {
    Vec3 centre = Vec3::Zero();
    for (std::size_t j = 0; j < m; ++j) centre += t.vertices[at(ring, j)];
    t.vertices.push_back(centre / static_cast<double>(m));
    const auto c = static_cast<Index>(t.vertices.size() - 1);
    for (std::size_t j = 0; j < m; ++j) {
      if (start)
        t.triangles.push_back({c, at(ring, j), at(ring, j + 1)});
      else
        t.triangles.push_back({c, at(ring, j + 1), at(ring, j)});
    }
  };
  cap(0, true);
  cap(rings - 1, false);
  return t;
}

Scene tubeCoil(const SceneParams& p) {
  // A loose helix of soft tube, its axis leaning, dropped on the ground: each coil lands on and
  // across the one below it. The coils start 0.3 apart (the rest shape is the initial shape, so
  // what touches at rest would never count as a self contact).
  Scene s;
  s.title = "a long soft tube in a loose helix dropped onto the ground, coiling onto itself";
  s.gravity = {0, -kGravity, 0};
  s.dt = kPileStep;
  s.statics.push_back(ground());
  TriMesh t = helixTube(0.9, 0.6, 3.0, 0.15, p.resolution);
  t.rotate(Vec3::UnitX(), 0.35);
  const Box b = boundsOf(t);
  t.translate({-0.5 * (b.lo.x() + b.hi.x()), 0.3 - b.lo.y(), -0.5 * (b.lo.z() + b.hi.z())});
  s.bodies.push_back(ball("tube", std::move(t)));
  return s;
}

Scene meshDrop(const SceneParams& p, std::size_t k) {
  Scene s;
  std::string path = p.mesh_file;
#ifdef PSC_DEFAULT_MESH_FILE
  if (path.empty()) {
    std::error_code ec;
    if (std::filesystem::exists(PSC_DEFAULT_MESH_FILE, ec)) path = PSC_DEFAULT_MESH_FILE;
  }
#endif
  TriMesh base;
  if (path.empty()) {
    base = makeFork(2.0, 0.2, p.resolution);
    s.note = "no --mesh given and assimp-testmodels not installed: built-in fork";
  } else {
    MeshFileInfo info;
    base = loadMeshFile(path, &info);
    const std::size_t dropped = keepLargestPiece(base);
    info.subdivisions = subdivideToward(base, p.resolution);
    s.note = path + ": " + std::to_string(base.vertices.size()) + " vertices, " +
             std::to_string(base.triangles.size()) + " triangles" +
             (dropped ? " (largest of " + std::to_string(dropped + 1) + " pieces)" : std::string()) +
             (info.subdivisions ? ", " + std::to_string(info.subdivisions) + " subdivision(s)" : std::string());
  }
  normalizeMesh(base, 0.8);
  s.title = std::to_string(k) + " copies of a mesh dropped onto each other";
  s.gravity = {0, -kGravity, 0};
  s.dt = kPileStep;
  s.statics.push_back(ground());
  Random rng(p.seed);
  const bool closed = isClosed(base);
  for (std::size_t i = 0; i < k; ++i) {
    TriMesh m = base;
    m.rotate(rng.unitVector(), rng.uniform(0, 2 * kPi));
    const Box b = boundsOf(m);
    m.translate({rng.uniform(-0.2, 0.2), 0.3 - b.lo.y() + 1.9 * static_cast<double>(i), rng.uniform(-0.2, 0.2)});
    SoftBodySpec body = closed ? ball("mesh_" + std::to_string(i), std::move(m)) : cloth("mesh_" + std::to_string(i), std::move(m));
    s.bodies.push_back(std::move(body));
  }
  return s;
}

}  // namespace

std::size_t Scene::resolution() const {
  if (bodies.empty()) return 0;
  std::size_t total = 0;
  for (const SoftBodySpec& b : bodies) total += b.mesh.vertices.size();
  return (total + bodies.size() / 2) / bodies.size();
}

const std::vector<SceneInfo>& sceneCatalog() {
  static const std::vector<SceneInfo> catalog = {
      {"head_on", "1", "two equal soft spheres meeting head-on (thesis case 1)", false, 2, 90},
      {"row", "2a", "three equal spheres in a row, the outer two moving in (thesis case 2)", false, 3, 90},
      {"row_mixed", "2b", "three spheres in a row, diameters D, D/2, D (thesis case 3)", false, 3, 90},
      {"interlock", "3", "two concave U shapes hooking into each other (thesis case 4)", false, 2, 90},
      {"tori_pile", "4", "a pile of soft tori on the ground (thesis case 5)", true, 6, 150},
      {"mixed_pile", "5", "spheres, tori and cloth dropped into a static box (thesis case 6)", true, 12, 150},
      {"cloth_ball", "6", "a cloth patch falling onto a soft ball (open surface)", false, 2, 120},
      {"fast_impact", "7", "a fast impact: 0.5 units per step, more than a region", false, 2, 60},
      {"mesh", "8", "a mesh file (--mesh) as soft bodies dropped onto copies of itself", true, 3, 150},
      {"projectile", "9", "a small soft sphere at 30 units/s into a large soft block (tunnelling)", false, 2, 60},
      {"fast_cloth", "10", "a soft ball at 20 units/s into a pinned cloth (tunnelling)", false, 2, 60},
      {"cloth_fold", "11", "a cloth dropped across a thin bar, falling folded onto itself (self-collision)", false, 1,
       180, 2000},
      {"tube_coil", "12", "a long soft tube in a loose helix coiling onto itself on the ground (self-collision)", false,
       1, 180},
  };
  return catalog;
}

const SceneInfo* findScene(const std::string& key) {
  for (const SceneInfo& s : sceneCatalog())
    if (s.name == key || s.number == key) return &s;
  if (key == "2") return findScene("2a");
  return nullptr;
}

Scene makeScene(const std::string& key, const SceneParams& asked) {
  const SceneInfo* info = findScene(key);
  if (!info) {
    std::string names;
    for (const SceneInfo& s : sceneCatalog()) names += (names.empty() ? "" : ", ") + s.name;
    throw badParam("unknown scene '" + key + "' (known: " + names + ")");
  }
  SceneParams p = asked;
  if (p.resolution == 0) p.resolution = info->default_resolution;
  if (p.resolution < 14) throw badParam("resolution " + std::to_string(p.resolution) + " is below 14 vertices per body");
  Scene s;
  const std::string& n = info->name;
  if (n == "head_on") s = headOn(p);
  else if (n == "row") s = row(p, false);
  else if (n == "row_mixed") s = row(p, true);
  else if (n == "interlock") s = interlock(p);
  else if (n == "tori_pile") s = toriPile(p, bodyCount(p, *info));
  else if (n == "mixed_pile") s = mixedPile(p, bodyCount(p, *info));
  else if (n == "cloth_ball") s = clothBall(p);
  else if (n == "fast_impact") s = fastImpact(p);
  else if (n == "projectile") s = projectile(p);
  else if (n == "fast_cloth") s = fastCloth(p);
  else if (n == "cloth_fold") s = clothFold(p);
  else if (n == "tube_coil") s = tubeCoil(p);
  else s = meshDrop(p, bodyCount(p, *info));
  s.name = n;
  s.default_steps = info->default_steps;
  // Within [kMinScale, kMaxScale]: beyond it single-precision Bullet's squared lengths and
  // volumes leave float's range and the scene diverges at its first step (a review's finding,
  // stop 46: --scale 1e308 and 1e-300 ran, reported a divergence and exited 0).
  if (!(p.scale >= kMinScale && p.scale <= kMaxScale)) {
    std::ostringstream what;
    what << "scale " << p.scale << " is outside [" << kMinScale << ", " << kMaxScale
         << "]: single-precision Bullet's squared lengths and volumes would leave float's range";
    throw badParam(what.str());
  }
  if (p.scale != 1.0) {
    // Lengths ×k with the same dt: velocities and accelerations ×k as well. Bullet's volume force
    // grows as area × volume (k⁵) against an acceleration that grows as k, hence kVC × k⁻⁴; the
    // position-based links and contacts are scale-free.
    const double k = p.scale;
    for (SoftBodySpec& b : s.bodies) {
      b.mesh.scale(k);
      b.velocity *= k;
      b.margin *= k;
      b.volume_conservation /= k * k * k * k;
    }
    for (StaticBoxSpec& box : s.statics) {
      box.center *= k;
      box.half_extents *= k;
    }
    s.gravity *= k;
    s.note += std::string(s.note.empty() ? "" : "; ") + "lengths scaled by " + std::to_string(k);
  }
  s.scale = p.scale;
  for (SoftBodySpec& b : s.bodies) {
    b.closed = isClosed(b.mesh);
    if (!b.closed) {
      b.volume_conservation = b.pressure = 0.0;  // Bullet's volume needs a closed surface
    } else if (b.pressure > 0) {
      // Bullet's pressure force per node is area·kPR/V: scale by V/A so that thin bodies (tori,
      // tubes) are not blown up harder than balls. A unit ball keeps b.pressure as given.
      double area = 0, volume = 0;
      for (const Triangle& t : b.mesh.triangles) {
        const Vec3 &p0 = b.mesh.vertices[t[0]], &p1 = b.mesh.vertices[t[1]], &p2 = b.mesh.vertices[t[2]];
        area += 0.5 * (p1 - p0).cross(p2 - p0).norm();
        volume += p0.dot(p1.cross(p2)) / 6.0;
      }
      if (area > 0) b.pressure *= 3.0 * std::abs(volume) / area;
    }
  }
  return s;
}

bool isClosed(const TriMesh& mesh) {
  // Directed edge counts: closed and consistently wound means each (a, b) once and (b, a) once.
  std::map<std::pair<Index, Index>, int> directed;
  for (const Triangle& t : mesh.triangles)
    for (std::size_t k = 0; k < 3; ++k)
      if (++directed[{t[k], t[(k + 1) % 3]}] > 1) return false;
  for (const auto& [e, c] : directed)
    if (!directed.count({e.second, e.first})) return false;
  return !mesh.triangles.empty();
}

}  // namespace psc::demo
