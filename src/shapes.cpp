#include "psc/shapes.h"

#include "psc/error.h"

#include <Eigen/Geometry>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <map>
#include <string>
#include <utility>

namespace psc {
namespace {

constexpr double kPi = 3.14159265358979323846;

void requirePositive(double value, const char* what, const char* shape) {
  if (!(value > 0.0) || !std::isfinite(value)) {
    throw Error(ErrorCode::InvalidArgument,
                std::string(shape) + ": " + what + " must be positive and finite, got " + std::to_string(value));
  }
}

void requireAtLeast(std::size_t value, std::size_t minimum, const char* what, const char* shape) {
  if (value < minimum) {
    throw Error(ErrorCode::InvalidArgument, std::string(shape) + ": " + what + " must be at least " +
                                                std::to_string(minimum) + ", got " + std::to_string(value));
  }
}

Index idx(std::size_t i) { return static_cast<Index>(i); }

Index addVertex(TriMesh& mesh, const Vec3& p) {
  mesh.vertices.push_back(p);
  return idx(mesh.vertices.size() - 1);
}

// Picks the tessellation (a, b) whose count(a, b) is closest to `target`. b/a should stay within a
// factor 2 of `aspect` so that the closest count does not come from a needle-like grid; a shape
// outside that window wins only when the window cannot come within target/2 of the request (tiny
// requests). Ties go to the aspect nearest the wanted one, then to the smaller a. count must grow
// with a and with b.
template <class CountFn>
std::pair<std::size_t, std::size_t> closestGrid(std::size_t target, std::size_t min_a, std::size_t min_b,
                                                double aspect, CountFn count) {
  std::pair<std::size_t, std::size_t> best{min_a, min_b};
  double best_score = std::numeric_limits<double>::infinity();
  double best_aspect_err = std::numeric_limits<double>::infinity();
  for (std::size_t a = min_a;; ++a) {
    const double ideal_b = aspect * double(a);
    const auto window_lo = static_cast<std::size_t>(std::floor(0.5 * ideal_b));
    const auto hi = std::max<std::size_t>(min_b, static_cast<std::size_t>(std::ceil(2.0 * ideal_b)));
    if (a > min_a && double(count(a, std::max(min_b, window_lo))) > 2.0 * double(target)) break;
    for (std::size_t b = min_b; b <= hi; ++b) {
      const double penalty = b < window_lo ? 0.5 * double(target) : 0.0;
      const double score = std::fabs(double(count(a, b)) - double(target)) + penalty;
      const double aspect_err = std::fabs(std::log(double(b) / ideal_b));
      if (score < best_score || (score == best_score && aspect_err < best_aspect_err)) {
        best = {a, b};
        best_score = score;
        best_aspect_err = aspect_err;
      }
    }
  }
  return best;
}

// Joins consecutive loops of equal length into a tube. Loops are ordered so that, walking along the
// tube direction T, each loop turns from N = T × Z toward Z (right-handed about T): then the quads
// (i,j),(i+1,j),(i+1,j+1) face outward. The first loop's edges end up traversed j+1 → j and the
// last loop's j → j+1, which is what lets tubes share a loop with consistent winding.
void stitchLoops(TriMesh& mesh, const std::vector<std::vector<Index>>& loops) {
  for (std::size_t i = 0; i + 1 < loops.size(); ++i) {
    const auto& a = loops[i];
    const auto& b = loops[i + 1];
    const std::size_t n = a.size();
    for (std::size_t j = 0; j < n; ++j) {
      const std::size_t k = (j + 1) % n;
      mesh.triangles.push_back({a[j], b[j], b[k]});
      mesh.triangles.push_back({a[j], b[k], a[k]});
    }
  }
}

// Closes a loop with a fan around a new centre vertex. `facing_back`: the cap faces against the
// tube direction (the tube's start).
void capLoop(TriMesh& mesh, const std::vector<Index>& loop, bool facing_back) {
  Vec3 c = Vec3::Zero();
  for (Index v : loop) c += mesh.vertices[v];
  c /= double(loop.size());
  const Index centre = addVertex(mesh, c);
  const std::size_t n = loop.size();
  for (std::size_t j = 0; j < n; ++j) {
    const Index a = loop[j];
    const Index b = loop[(j + 1) % n];
    if (facing_back) {
      mesh.triangles.push_back({centre, a, b});
    } else {
      mesh.triangles.push_back({centre, b, a});
    }
  }
}

// A planar centreline in the xy plane, sampled by arc length; the tube's frame is Z = +z and
// N = T × Z, so loop points C + r(cos φ N + sin φ Z) turn from N to Z as stitchLoops expects.
std::vector<Index> addRing(TriMesh& mesh, const Vec3& centre, const Vec3& tangent, double radius, std::size_t n) {
  const Vec3 z = Vec3::UnitZ();
  const Vec3 normal = tangent.cross(z).normalized();
  std::vector<Index> loop(n);
  for (std::size_t j = 0; j < n; ++j) {
    const double phi = 2.0 * kPi * double(j) / double(n);
    loop[j] = addVertex(mesh, centre + radius * (std::cos(phi) * normal + std::sin(phi) * z));
  }
  return loop;
}

double smoothstep(double t) {
  t = std::clamp(t, 0.0, 1.0);
  return t * t * (3.0 - 2.0 * t);
}

}  // namespace

TriMesh& TriMesh::translate(const Vec3& offset) {
  if (!offset.allFinite()) throw Error(ErrorCode::InvalidArgument, "TriMesh::translate: offset is not finite");
  for (Vec3& v : vertices) v += offset;
  return *this;
}

TriMesh& TriMesh::scale(double factor) {
  // A negative factor would turn the mesh inside out (winding flips), zero would collapse it.
  requirePositive(factor, "factor", "TriMesh::scale");
  for (Vec3& v : vertices) v *= factor;
  return *this;
}

TriMesh& TriMesh::rotate(const Vec3& axis, double radians) {
  const double n = axis.norm();
  if (!(n > 0.0) || !std::isfinite(n) || !std::isfinite(radians)) {
    throw Error(ErrorCode::InvalidArgument, "TriMesh::rotate: axis must be non-zero and finite, angle finite");
  }
  const Eigen::Matrix3d r = Eigen::AngleAxisd(radians, axis / n).toRotationMatrix();
  for (Vec3& v : vertices) v = r * v;
  return *this;
}

TriMesh makeSphere(double radius, std::size_t vertex_count) {
  requirePositive(radius, "radius", "makeSphere");
  requireAtLeast(vertex_count, 14, "vertex_count", "makeSphere");
  // rings × segments + 2 poles; segments ≈ 2 × rings keeps the quads near square at the equator.
  // Plain variables, not a structured binding: C++17 lambdas cannot capture bindings (clang rejects it).
  const std::pair<std::size_t, std::size_t> grid =
      closestGrid(vertex_count, 2, 3, 2.0, [](std::size_t a, std::size_t b) { return a * b + 2; });
  const std::size_t rings = grid.first, segments = grid.second;
  TriMesh mesh;
  mesh.vertices.reserve(rings * segments + 2);
  const Index north = addVertex(mesh, Vec3(0, 0, radius));
  for (std::size_t i = 1; i <= rings; ++i) {
    const double theta = kPi * double(i) / double(rings + 1);
    for (std::size_t j = 0; j < segments; ++j) {
      const double phi = 2.0 * kPi * double(j) / double(segments);
      addVertex(mesh, radius * Vec3(std::sin(theta) * std::cos(phi), std::sin(theta) * std::sin(phi),
                                    std::cos(theta)));
    }
  }
  const Index south = addVertex(mesh, Vec3(0, 0, -radius));
  auto at = [&](std::size_t ring, std::size_t seg) { return idx(1 + (ring - 1) * segments + seg % segments); };
  for (std::size_t j = 0; j < segments; ++j) {
    mesh.triangles.push_back({north, at(1, j), at(1, j + 1)});
    for (std::size_t i = 1; i < rings; ++i) {
      mesh.triangles.push_back({at(i, j), at(i + 1, j), at(i + 1, j + 1)});
      mesh.triangles.push_back({at(i, j), at(i + 1, j + 1), at(i, j + 1)});
    }
    mesh.triangles.push_back({south, at(rings, j + 1), at(rings, j)});
  }
  return mesh;
}

TriMesh makeIcosphere(double radius, int subdivisions) {
  requirePositive(radius, "radius", "makeIcosphere");
  if (subdivisions < 0 || subdivisions > 8) {
    throw Error(ErrorCode::InvalidArgument,
                "makeIcosphere: subdivisions must be in [0, 8] (8 = 655362 vertices), got " +
                    std::to_string(subdivisions));
  }
  const double t = (1.0 + std::sqrt(5.0)) / 2.0;
  TriMesh mesh;
  const double base[12][3] = {{-1, t, 0}, {1, t, 0}, {-1, -t, 0}, {1, -t, 0}, {0, -1, t}, {0, 1, t},
                              {0, -1, -t}, {0, 1, -t}, {t, 0, -1}, {t, 0, 1}, {-t, 0, -1}, {-t, 0, 1}};
  for (const auto& p : base) mesh.vertices.push_back(Vec3(p[0], p[1], p[2]).normalized());
  mesh.triangles = {{0, 11, 5}, {0, 5, 1},  {0, 1, 7},   {0, 7, 10}, {0, 10, 11}, {1, 5, 9}, {5, 11, 4},
                    {11, 10, 2}, {10, 7, 6}, {7, 1, 8},   {3, 9, 4},  {3, 4, 2},   {3, 2, 6}, {3, 6, 8},
                    {3, 8, 9},  {4, 9, 5},  {2, 4, 11},  {6, 2, 10}, {8, 6, 7},   {9, 8, 1}};
  for (int level = 0; level < subdivisions; ++level) {
    std::map<std::pair<Index, Index>, Index> midpoint;
    auto mid = [&](Index a, Index b) {
      const auto key = std::minmax(a, b);
      const auto it = midpoint.find(key);
      if (it != midpoint.end()) return it->second;
      const Index m = addVertex(mesh, (mesh.vertices[a] + mesh.vertices[b]).normalized());
      midpoint.emplace(key, m);
      return m;
    };
    std::vector<Triangle> next;
    next.reserve(mesh.triangles.size() * 4);
    for (const Triangle& tri : mesh.triangles) {
      const Index ab = mid(tri[0], tri[1]);
      const Index bc = mid(tri[1], tri[2]);
      const Index ca = mid(tri[2], tri[0]);
      next.push_back({tri[0], ab, ca});
      next.push_back({tri[1], bc, ab});
      next.push_back({tri[2], ca, bc});
      next.push_back({ab, bc, ca});
    }
    mesh.triangles = std::move(next);
  }
  for (Vec3& v : mesh.vertices) v *= radius;
  return mesh;
}

TriMesh makeTorus(double major_radius, double minor_radius, std::size_t vertex_count) {
  requirePositive(major_radius, "major_radius", "makeTorus");
  requirePositive(minor_radius, "minor_radius", "makeTorus");
  if (!(minor_radius < major_radius)) {
    throw Error(ErrorCode::InvalidArgument, "makeTorus: minor_radius must be smaller than major_radius");
  }
  requireAtLeast(vertex_count, 9, "vertex_count", "makeTorus");
  // Square-ish quads: segments around the axis / segments around the tube ≈ R / r.
  const auto [tube, around] = closestGrid(vertex_count, 3, 3, major_radius / minor_radius,
                                          [](std::size_t a, std::size_t b) { return a * b; });
  TriMesh mesh;
  mesh.vertices.reserve(tube * around);
  std::vector<std::vector<Index>> loops;
  for (std::size_t i = 0; i < around; ++i) {
    const double u = 2.0 * kPi * double(i) / double(around);
    const Vec3 centre(major_radius * std::cos(u), major_radius * std::sin(u), 0.0);
    const Vec3 tangent(-std::sin(u), std::cos(u), 0.0);
    loops.push_back(addRing(mesh, centre, tangent, minor_radius, tube));
  }
  loops.push_back(loops.front());
  stitchLoops(mesh, loops);
  return mesh;
}

TriMesh makeBox(const Vec3& half_extents, std::size_t vertex_count) {
  for (int a = 0; a < 3; ++a) requirePositive(half_extents[a], "every half extent", "makeBox");
  requireAtLeast(vertex_count, 8, "vertex_count", "makeBox");
  // Segments per axis proportional to the extent so the faces carry near-square cells; the surface
  // lattice of an a×b×c grid has (a+1)(b+1)(c+1) − (a−1)(b−1)(c−1) vertices.
  const double longest = half_extents.maxCoeff();
  auto segmentsFor = [&](std::size_t s) {
    std::array<std::size_t, 3> n{};
    for (int a = 0; a < 3; ++a) {
      n[a] = std::max<std::size_t>(1, static_cast<std::size_t>(std::lround(double(s) * half_extents[a] / longest)));
    }
    return n;
  };
  auto surfaceCount = [](const std::array<std::size_t, 3>& n) {
    auto in = [](std::size_t k) { return k >= 1 ? k - 1 : 0; };
    return (n[0] + 1) * (n[1] + 1) * (n[2] + 1) - in(n[0]) * in(n[1]) * in(n[2]);
  };
  std::array<std::size_t, 3> seg = segmentsFor(1);
  double best_err = std::fabs(double(surfaceCount(seg)) - double(vertex_count));
  for (std::size_t s = 2;; ++s) {
    const auto candidate = segmentsFor(s);
    const double err = std::fabs(double(surfaceCount(candidate)) - double(vertex_count));
    if (err < best_err) {
      best_err = err;
      seg = candidate;
    }
    if (double(surfaceCount(candidate)) > 2.0 * double(vertex_count)) break;
  }

  TriMesh mesh;
  // Lattice points are shared between faces through this map, so edges and corners are single
  // vertices and the box is one closed manifold.
  std::map<std::array<std::size_t, 3>, Index> lattice;
  auto vertexAt = [&](const std::array<std::size_t, 3>& g) {
    const auto it = lattice.find(g);
    if (it != lattice.end()) return it->second;
    Vec3 p;
    for (int a = 0; a < 3; ++a) p[a] = half_extents[a] * (2.0 * double(g[a]) / double(seg[a]) - 1.0);
    const Index v = addVertex(mesh, p);
    lattice.emplace(g, v);
    return v;
  };
  for (int axis = 0; axis < 3; ++axis) {
    const int u = (axis + 1) % 3;
    const int w = (axis + 2) % 3;  // e_u × e_w = e_axis
    for (int side = 0; side < 2; ++side) {
      for (std::size_t i = 0; i < seg[u]; ++i) {
        for (std::size_t j = 0; j < seg[w]; ++j) {
          auto corner = [&](std::size_t di, std::size_t dj) {
            std::array<std::size_t, 3> g{};
            g[axis] = side == 0 ? 0 : seg[axis];
            g[u] = i + di;
            g[w] = j + dj;
            return vertexAt(g);
          };
          const Index p00 = corner(0, 0), p10 = corner(1, 0), p11 = corner(1, 1), p01 = corner(0, 1);
          if (side == 1) {
            mesh.triangles.push_back({p00, p10, p11});
            mesh.triangles.push_back({p00, p11, p01});
          } else {
            mesh.triangles.push_back({p00, p11, p10});
            mesh.triangles.push_back({p00, p01, p11});
          }
        }
      }
    }
  }
  return mesh;
}

TriMesh makeUShape(double width, double arm_length, double tube_radius, std::size_t vertex_count) {
  requirePositive(width, "width", "makeUShape");
  requirePositive(arm_length, "arm_length", "makeUShape");
  requirePositive(tube_radius, "tube_radius", "makeUShape");
  if (!(2.0 * tube_radius < width)) {
    throw Error(ErrorCode::InvalidArgument, "makeUShape: width must exceed twice the tube radius (the bend "
                                            "would fold onto itself)");
  }
  requireAtLeast(vertex_count, 32, "vertex_count", "makeUShape");
  // Centreline: left arm down from (−w/2, L) to (−w/2, 0), the lower half circle of radius w/2, the
  // right arm up to (w/2, L). Arc length s ∈ [0, S].
  const double bend = 0.5 * width;
  const double arc = kPi * bend;
  const double total = 2.0 * arm_length + arc;
  auto point = [&](double s, Vec3& c, Vec3& tangent) {
    if (s <= arm_length) {
      c = Vec3(-bend, arm_length - s, 0);
      tangent = Vec3(0, -1, 0);
    } else if (s <= arm_length + arc) {
      const double a = kPi + (s - arm_length) / bend;  // from angle π (left) through 3π/2 (bottom)
      c = Vec3(bend * std::cos(a), bend * std::sin(a), 0);
      tangent = Vec3(-std::sin(a), std::cos(a), 0);
    } else {
      c = Vec3(bend, s - arm_length - arc, 0);
      tangent = Vec3(0, 1, 0);
    }
  };
  // Ring spacing along the centreline ≈ spacing around the tube; at least 9 rings so the bend
  // stays a bend.
  const auto [around, rings] =
      closestGrid(vertex_count, 3, 9, total / (2.0 * kPi * tube_radius),
                  [](std::size_t a, std::size_t b) { return a * b + 2; });
  TriMesh mesh;
  std::vector<std::vector<Index>> loops;
  for (std::size_t i = 0; i < rings; ++i) {
    Vec3 c, tangent;
    point(total * double(i) / double(rings - 1), c, tangent);
    loops.push_back(addRing(mesh, c, tangent, tube_radius, around));
  }
  stitchLoops(mesh, loops);
  capLoop(mesh, loops.front(), true);
  capLoop(mesh, loops.back(), false);
  return mesh;
}

TriMesh makeFork(double length, double tube_radius, std::size_t vertex_count) {
  requirePositive(length, "length", "makeFork");
  requirePositive(tube_radius, "tube_radius", "makeFork");
  if (!(length > 4.0 * tube_radius)) {
    throw Error(ErrorCode::InvalidArgument, "makeFork: length must exceed four tube radii");
  }
  requireAtLeast(vertex_count, 40, "vertex_count", "makeFork");
  // One closed genus-0 surface ("pair of pants" with capped legs), along +y: a handle from
  // y = −L/2 to the junction at y = 0 whose cross-section widens from a circle to an ellipse
  // (semi-axes d + r in x, r in z), and two prongs centred at x = ∓d from y = 0 to y = L/2.
  // At the junction, a chain of crotch vertices along x = 0 closes each half of the handle's last
  // loop into a prong's first loop; the chain is shared by both prongs, so every edge has exactly
  // two triangles. Prong A keeps x ≤ 0 and prong B x ≥ 0, so the prongs never cross.
  const double r = tube_radius;
  const double d = 2.0 * r;
  const double half = 0.5 * length;
  // Half a handle loop has k vertices; the crotch chain spans 2r at about the loop's spacing.
  auto crotchFor = [&](std::size_t k) {
    const double spacing = kPi * r / double(k);
    return std::max<long>(1, std::lround(2.0 * r / spacing) - 1);
  };
  // handle_rings loops along the handle, one fewer along each prong: count(k, handle_rings).
  const auto [k, handle_rings] = closestGrid(
      vertex_count, 2, 3, half / (kPi * r), [&](std::size_t kk, std::size_t h) {
        return h * 2 * kk + 2 * (h - 1) * (kk + 1 + static_cast<std::size_t>(crotchFor(kk))) + 3;
      });
  struct {
    std::size_t crotch, handle_rings, prong_rings;
  } const layout{static_cast<std::size_t>(crotchFor(k)), handle_rings, handle_rings - 1};
  const std::size_t ring = 2 * k;

  TriMesh mesh;
  // Handle loops: angle φ from π/2 (top, x = 0, z = r) increasing, so index 0 is the top and index
  // k the bottom, and the loop turns from +x toward +z as stitchLoops wants for T = +y.
  std::vector<std::vector<Index>> handle;
  const double flare_start = -0.4 * half;
  for (std::size_t i = 0; i < layout.handle_rings; ++i) {
    const double y = -half + half * double(i) / double(layout.handle_rings - 1);
    const double a = r + d * smoothstep((y - flare_start) / (0.0 - flare_start));
    std::vector<Index> loop(ring);
    for (std::size_t j = 0; j < ring; ++j) {
      const double phi = 0.5 * kPi + 2.0 * kPi * double(j) / double(ring);
      loop[j] = addVertex(mesh, Vec3(a * std::cos(phi), y, r * std::sin(phi)));
    }
    handle.push_back(std::move(loop));
  }
  stitchLoops(mesh, handle);
  capLoop(mesh, handle.front(), true);

  const std::vector<Index>& junction = handle.back();
  std::vector<Index> crotch(layout.crotch);  // top to bottom along x = 0
  for (std::size_t c = 0; c < layout.crotch; ++c) {
    const double z = r - 2.0 * r * double(c + 1) / double(layout.crotch + 1);
    crotch[c] = addVertex(mesh, Vec3(0, 0, z));
  }
  std::vector<Index> start_a, start_b;  // both turn from +x toward +z about +y
  for (std::size_t j = 0; j <= k; ++j) start_a.push_back(junction[j]);
  for (std::size_t c = layout.crotch; c-- > 0;) start_a.push_back(crotch[c]);
  for (std::size_t j = k; j <= ring; ++j) start_b.push_back(junction[j % ring]);
  for (std::size_t c = 0; c < layout.crotch; ++c) start_b.push_back(crotch[c]);

  const double prong_spacing = half / double(layout.prong_rings);
  const std::size_t blend_rings = std::max<std::size_t>(1, layout.prong_rings / 2);
  auto buildProng = [&](const std::vector<Index>& start, double centre_x, double start_angle) {
    // Each start vertex goes to the prong circle at the angle given by its arc-length fraction along
    // the start loop, which keeps the order of the loop and so a simple, untwisted tube.
    const std::size_t n = start.size();
    std::vector<double> arclen(n + 1, 0.0);
    for (std::size_t j = 0; j < n; ++j) {
      arclen[j + 1] = arclen[j] + (mesh.vertices[start[(j + 1) % n]] - mesh.vertices[start[j]]).norm();
    }
    std::vector<Vec3> from(n), to(n);
    for (std::size_t j = 0; j < n; ++j) {
      from[j] = mesh.vertices[start[j]];
      const double phi = start_angle + 2.0 * kPi * arclen[j] / arclen[n];
      to[j] = Vec3(centre_x + r * std::cos(phi), 0, r * std::sin(phi));
    }
    std::vector<std::vector<Index>> loops{start};
    for (std::size_t i = 1; i <= layout.prong_rings; ++i) {
      const double t = smoothstep(double(i) / double(blend_rings));
      const double y = prong_spacing * double(i);
      std::vector<Index> loop(n);
      for (std::size_t j = 0; j < n; ++j) {
        Vec3 p = (1.0 - t) * from[j] + t * to[j];
        p.y() = y;
        loop[j] = addVertex(mesh, p);
      }
      loops.push_back(std::move(loop));
    }
    stitchLoops(mesh, loops);
    capLoop(mesh, loops.back(), false);
  };
  buildProng(start_a, -d, 0.5 * kPi);   // starts at the top, turning through −x
  buildProng(start_b, d, -0.5 * kPi);   // starts at the bottom, turning through +x
  return mesh;
}

TriMesh makePatch(double width, double height, std::size_t nx, std::size_t ny) {
  requirePositive(width, "width", "makePatch");
  requirePositive(height, "height", "makePatch");
  requireAtLeast(nx, 2, "nx", "makePatch");
  requireAtLeast(ny, 2, "ny", "makePatch");
  TriMesh mesh;
  mesh.vertices.reserve(nx * ny);
  for (std::size_t j = 0; j < ny; ++j) {
    for (std::size_t i = 0; i < nx; ++i) {
      mesh.vertices.emplace_back(width * (double(i) / double(nx - 1) - 0.5),
                                 height * (double(j) / double(ny - 1) - 0.5), 0.0);
    }
  }
  auto at = [&](std::size_t i, std::size_t j) { return idx(j * nx + i); };
  for (std::size_t j = 0; j + 1 < ny; ++j) {
    for (std::size_t i = 0; i + 1 < nx; ++i) {
      mesh.triangles.push_back({at(i, j), at(i + 1, j), at(i + 1, j + 1)});
      mesh.triangles.push_back({at(i, j), at(i + 1, j + 1), at(i, j + 1)});
    }
  }
  return mesh;
}

}  // namespace psc
