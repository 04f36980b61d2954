#include "psc/budget.h"

#include "psc/error.h"

#include <Eigen/Geometry>
#include <hacdHACD.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <limits>
#include <map>
#include <mutex>
#include <numeric>
#include <string>
#include <unordered_map>
#include <utility>

namespace psc {
namespace {

// HACD::NormalizeData subtracts the barycentre and scales the points so that their bounding-box
// diagonal becomes 2 × scale; the concavity threshold is compared in those units, so a fraction f
// of the diagonal is f × 2 × scale.
constexpr double kHacdScale = 1000.0;

// HACD keeps process-wide state (the global `gCancelRequest`, reset inside Compute), so two
// decompositions must not run at the same time.
std::mutex& hacdMutex() {
  static std::mutex m;
  return m;
}

void checkSettings(const DecompositionSettings& s) {
  auto fail = [](const std::string& what) { throw Error(ErrorCode::InvalidSettings, "DecompositionSettings: " + what); };
  if (!(s.concavity > 0.0) || !std::isfinite(s.concavity)) fail("concavity must be positive and finite");
  if (s.min_parts < 1) fail("min_parts must be at least 1");
  if (s.max_hull_vertices < 4) fail("max_hull_vertices must be at least 4");
  if (s.max_input_triangles < 8) fail("max_input_triangles must be at least 8");
}

// The mesh HACD actually sees: either the body's own triangles or a vertex-clustered copy. Each
// proxy vertex carries the area-weighted normal of the surface it stands for, used by the merge
// pass's convexity test.
struct Proxy {
  std::vector<Vec3> points;
  std::vector<Vec3> normals;
  std::vector<Triangle> triangles;
  std::vector<Index> proxy_of;  ///< original vertex → proxy vertex; kInvalidIndex if in no triangle
};

// Clusters original vertices by `key` (a cell id, or the vertex itself) and keeps the triangles
// that still span three distinct proxy vertices, once each, with non-zero area.
template <class KeyFn>
Proxy buildProxy(const MeshTopology& topology, const PositionView& positions, KeyFn key) {
  Proxy p;
  const std::size_t m = topology.vertexCount();
  p.proxy_of.assign(m, kInvalidIndex);
  std::unordered_map<std::uint64_t, Index> index_of_key;
  std::vector<double> members;
  // Proxy ids in order of first appearance over ascending original vertex indices: deterministic.
  for (std::size_t v = 0; v < m; ++v) {
    if (topology.vertexTriangles(static_cast<Index>(v)).empty()) continue;
    const auto [it, inserted] = index_of_key.emplace(key(v), static_cast<Index>(p.points.size()));
    if (inserted) {
      p.points.push_back(Vec3::Zero());
      p.normals.push_back(Vec3::Zero());
      members.push_back(0.0);
    }
    p.proxy_of[v] = it->second;
    p.points[it->second] += positions[v];
    members[it->second] += 1.0;
  }
  for (std::size_t i = 0; i < p.points.size(); ++i) p.points[i] /= members[i];

  std::map<std::array<Index, 3>, bool> seen;
  for (const Triangle& t : topology.triangles()) {
    const Vec3 a = positions[t[0]], b = positions[t[1]], c = positions[t[2]];
    const Vec3 area_normal = (b - a).cross(c - a);
    Triangle q{p.proxy_of[t[0]], p.proxy_of[t[1]], p.proxy_of[t[2]]};
    for (Index v : q) p.normals[v] += area_normal;
    if (q[0] == q[1] || q[1] == q[2] || q[0] == q[2]) continue;
    std::array<Index, 3> sorted = q;
    std::sort(sorted.begin(), sorted.end());
    if (!seen.emplace(sorted, true).second) continue;
    const Vec3 qa = p.points[q[0]], qb = p.points[q[1]], qc = p.points[q[2]];
    const double scale = std::max({(qb - qa).squaredNorm(), (qc - qa).squaredNorm(), (qc - qb).squaredNorm()});
    if (!((qb - qa).cross(qc - qa).norm() > 1e-12 * scale)) continue;
    p.triangles.push_back(q);
  }
  for (Vec3& n : p.normals) {
    const double len = n.norm();
    n = len > 0.0 ? Vec3(n / len) : Vec3::Zero();
  }
  return p;
}

// Vertex clustering on a uniform grid, with the cell grown until the proxy has at most `target`
// triangles. Linear in the mesh size per attempt; the first cell size comes from the surface area,
// so a few attempts suffice.
Proxy decimate(const MeshTopology& topology, const PositionView& positions, std::size_t target) {
  Vec3 lo = Vec3::Constant(std::numeric_limits<double>::infinity());
  Vec3 hi = -lo;
  double area = 0.0;
  for (const Triangle& t : topology.triangles()) {
    const Vec3 a = positions[t[0]], b = positions[t[1]], c = positions[t[2]];
    area += 0.5 * (b - a).cross(c - a).norm();
    lo = lo.cwiseMin(a).cwiseMin(b).cwiseMin(c);
    hi = hi.cwiseMax(a).cwiseMax(b).cwiseMax(c);
  }
  const double diagonal = (hi - lo).norm();
  // A closed surface has about two triangles per vertex; one vertex per occupied cell.
  double cell = std::max(std::sqrt(2.0 * area / double(target)), 1e-6 * diagonal);
  Proxy best;
  for (int attempt = 0; attempt < 64; ++attempt) {
    const double inv = 1.0 / cell;
    auto key = [&](std::size_t v) {
      const Vec3 g = ((positions[v] - lo) * inv).array().floor();
      // 21 bits per axis: the grid never has more than 2^21 cells across (cell ≥ 1e-6 diagonal).
      return (static_cast<std::uint64_t>(g.x()) << 42) | (static_cast<std::uint64_t>(g.y()) << 21) |
             static_cast<std::uint64_t>(g.z());
    };
    best = buildProxy(topology, positions, key);
    if (best.triangles.size() <= target) break;
    cell *= 1.15;
  }
  return best;
}

// Runs HACD on the proxy and labels each proxy vertex with the cluster most of its triangles
// belong to (ties: the lower cluster). Proxy vertices in no proxy triangle get kInvalidIndex.
// HACD's hull code (ICHull) double-frees on degenerate input; the fuzzer found three such inputs
// (fuzz/crashers/world/hacd_double_free*). It is only given closed, consistently wound surfaces (every
// directed edge once, and its reverse once) that enclose a clear volume; anything else, open
// sheets included, is labelled one part per connected piece, without HACD. Closedness also makes
// the signed volume below independent of the origin (the third crasher was a nearly flat open
// sheet whose "volume" came from its distance to the origin). Cost: shapes whose coincident
// vertices merge into a non-manifold proxy (makeFork's crotch) get one part, as do open meshes.
bool safeForHacd(const Proxy& proxy) {
  if (proxy.triangles.size() < 4) return false;
  std::map<std::pair<Index, Index>, int> directed;
  for (const Triangle& t : proxy.triangles)
    for (std::size_t k = 0; k < 3; ++k)
      if (++directed[{t[k], t[(k + 1) % 3]}] > 1) return false;  // a directed edge twice: bad winding
  for (const auto& edge : directed)
    if (directed.count({edge.first.second, edge.first.first}) == 0) return false;  // a border: open
  Vec3 lo = Vec3::Constant(std::numeric_limits<double>::infinity()), hi = -lo;
  double volume6 = 0.0;
  for (const Triangle& t : proxy.triangles) {
    const Vec3 &a = proxy.points[t[0]], &b = proxy.points[t[1]], &c = proxy.points[t[2]];
    volume6 += a.dot(b.cross(c));
    lo = lo.cwiseMin(a).cwiseMin(b).cwiseMin(c);
    hi = hi.cwiseMax(a).cwiseMax(b).cwiseMax(c);
  }
  const double d = (hi - lo).norm();
  return std::isfinite(volume6) && volume6 > 1e-6 * d * d * d;
}

std::vector<Index> pieceLabels(const Proxy& proxy) {
  std::vector<Index> label(proxy.points.size(), kInvalidIndex);
  std::vector<Index> parent(proxy.points.size());
  for (std::size_t i = 0; i < parent.size(); ++i) parent[i] = static_cast<Index>(i);
  const auto root = [&](Index x) {
    while (parent[x] != x) x = parent[x] = parent[parent[x]];
    return x;
  };
  for (const Triangle& t : proxy.triangles)
    for (std::size_t k = 1; k < 3; ++k) {
      const Index a = root(t[0]), b = root(t[k]);
      if (a != b) parent[std::max(a, b)] = std::min(a, b);
    }
  std::map<Index, Index> piece;
  for (const Triangle& t : proxy.triangles)
    for (Index v : t) label[v] = piece.emplace(root(v), static_cast<Index>(piece.size())).first->second;
  return label;
}

std::vector<Index> hacdLabels(const Proxy& proxy, const DecompositionSettings& settings) {
  std::vector<Index> label(proxy.points.size(), kInvalidIndex);
  if (proxy.triangles.empty()) return label;
  if (!safeForHacd(proxy)) return pieceLabels(proxy);
  // HACD normalises the points it is given in place, hence the copy.
  std::vector<HACD::Vec3<HACD::Real>> points;
  points.reserve(proxy.points.size());
  for (const Vec3& v : proxy.points) points.emplace_back(v.x(), v.y(), v.z());
  std::vector<HACD::Vec3<long>> triangles;
  triangles.reserve(proxy.triangles.size());
  for (const Triangle& t : proxy.triangles) triangles.emplace_back(long(t[0]), long(t[1]), long(t[2]));

  std::vector<long> partition;
  std::size_t clusters = 0;
  {
    std::lock_guard<std::mutex> lock(hacdMutex());
    HACD::HACD hacd;
    hacd.SetPoints(points.data());
    hacd.SetNPoints(points.size());
    hacd.SetTriangles(triangles.data());
    hacd.SetNTriangles(triangles.size());
    hacd.SetScaleFactor(kHacdScale);
    hacd.SetConcavity(settings.concavity * 2.0 * kHacdScale);
    hacd.SetNClusters(settings.min_parts);
    hacd.SetNVerticesPerCH(settings.max_hull_vertices);
    // HACD's constructor leaves the face-points flag uninitialised; the extra distance points cost
    // O(F²) ray casts, which the proxy's size budget does not allow for.
    hacd.SetAddFacesPoints(false);
    hacd.SetAddExtraDistPoints(false);
    hacd.SetAddNeighboursDistPoints(false);
    if (!hacd.Compute()) {
      throw Error(ErrorCode::InvalidMesh, "decomposeConvex: HACD rejected the mesh");
    }
    clusters = hacd.GetNClusters();
    // GetPartition(): one cluster id per input triangle (HACD::Compute fills m_partition[t]).
    partition.assign(hacd.GetPartition(), hacd.GetPartition() + triangles.size());
  }

  std::vector<std::map<long, std::size_t>> votes(proxy.points.size());
  for (std::size_t t = 0; t < proxy.triangles.size(); ++t) {
    if (partition[t] < 0 || static_cast<std::size_t>(partition[t]) >= clusters) continue;
    for (Index v : proxy.triangles[t]) ++votes[v][partition[t]];
  }
  for (std::size_t v = 0; v < votes.size(); ++v) {
    std::size_t most = 0;
    for (const auto& [cluster, count] : votes[v]) {
      if (count > most) {
        most = count;
        label[v] = static_cast<Index>(cluster);
      }
    }
  }
  return label;
}

// How far a set of surface points is from convex: the largest height of one point above another's
// tangent plane, max over v, u of n_v · (u − v). Zero (up to rounding) for a convex surface whose
// vertex normals lie in their normal cones, and about the depth of the dent for a concave one.
double crossConcavity(const Proxy& proxy, const std::vector<Index>& from, const std::vector<Index>& to) {
  double worst = -std::numeric_limits<double>::infinity();
  for (Index v : from) {
    const Vec3& n = proxy.normals[v];
    const double base = n.dot(proxy.points[v]);
    for (Index u : to) worst = std::max(worst, n.dot(proxy.points[u]) - base);
  }
  return worst;
}

// HACD stops short of the last merges on closed convex surfaces (measured: a 42-vertex icosphere
// stays in 2 clusters even with an unbounded concavity, a 642-vertex one in 10 at 5 %) and merges
// clusters one triangle at a time. This pass finishes the job with a cheap exact criterion: merge
// the adjacent pair whose union is most convex while the union's concavity stays within the
// tolerance. It never splits, so HACD remains the judge of where a body is concave.
std::vector<Index> mergeConvexNeighbours(const Proxy& proxy, std::vector<Index> label, double tolerance,
                                         std::size_t min_parts) {
  Index count = 0;
  for (Index l : label) {
    if (l != kInvalidIndex) count = std::max<Index>(count, l + 1);
  }
  std::vector<std::vector<Index>> members(count);
  for (std::size_t v = 0; v < label.size(); ++v) {
    if (label[v] != kInvalidIndex) members[label[v]].push_back(static_cast<Index>(v));
  }
  std::vector<double> self(count, 0.0);
  std::size_t alive = 0;
  for (Index c = 0; c < count; ++c) {
    if (members[c].empty()) continue;
    ++alive;
    self[c] = crossConcavity(proxy, members[c], members[c]);
  }
  std::map<std::pair<Index, Index>, double> candidates;  // (a < b) → concavity of a ∪ b
  auto unionConcavity = [&](Index a, Index b) {
    return std::max({self[a], self[b], crossConcavity(proxy, members[a], members[b]),
                     crossConcavity(proxy, members[b], members[a])});
  };
  for (const Triangle& t : proxy.triangles) {
    for (int k = 0; k < 3; ++k) {
      const Index a = label[t[k]], b = label[t[(k + 1) % 3]];
      if (a == kInvalidIndex || b == kInvalidIndex || a == b) continue;
      const auto key = std::minmax(a, b);
      if (candidates.find(key) == candidates.end()) candidates.emplace(key, unionConcavity(key.first, key.second));
    }
  }
  while (alive > min_parts && !candidates.empty()) {
    auto best = candidates.begin();
    for (auto it = candidates.begin(); it != candidates.end(); ++it) {
      if (it->second < best->second) best = it;
    }
    if (!(best->second <= tolerance)) break;
    const auto [a, b] = best->first;
    self[a] = best->second;
    members[a].insert(members[a].end(), members[b].begin(), members[b].end());
    members[b].clear();
    for (Index v : members[a]) label[v] = a;
    --alive;
    std::vector<Index> neighbours;
    for (auto it = candidates.begin(); it != candidates.end();) {
      const auto [x, y] = it->first;
      if (x == a || x == b || y == a || y == b) {
        const Index other = (x == a || x == b) ? y : x;
        if (other != a && other != b) neighbours.push_back(other);
        it = candidates.erase(it);
      } else {
        ++it;
      }
    }
    std::sort(neighbours.begin(), neighbours.end());
    neighbours.erase(std::unique(neighbours.begin(), neighbours.end()), neighbours.end());
    for (Index n : neighbours) candidates.emplace(std::minmax(a, n), unionConcavity(std::min(a, n), std::max(a, n)));
  }
  return label;
}

// Per-vertex majority voting can leave a cluster with one or two proxy vertices, which spans no
// volume and is no convex part; each such cluster joins the neighbour it shares most edges with.
std::vector<Index> absorbSlivers(const Proxy& proxy, std::vector<Index> label, std::size_t min_parts) {
  constexpr std::size_t kMinVertices = 4;  // the fewest points that enclose a volume
  std::map<Index, std::size_t> size;
  for (Index l : label) {
    if (l != kInvalidIndex) ++size[l];
  }
  std::size_t alive = size.size();
  for (auto& [cluster, members] : size) {
    if (members >= kMinVertices || alive <= min_parts) continue;
    std::map<Index, std::size_t> shared;
    for (const Triangle& t : proxy.triangles) {
      for (int k = 0; k < 3; ++k) {
        const Index a = label[t[k]], b = label[t[(k + 1) % 3]];
        if (a == cluster && b != cluster && b != kInvalidIndex) ++shared[b];
      }
    }
    if (shared.empty()) continue;
    Index into = shared.begin()->first;
    for (const auto& [other, edges] : shared) {
      if (edges > shared[into]) into = other;
    }
    for (Index& l : label) {
      if (l == cluster) l = into;
    }
    size[into] += members;
    members = 0;
    --alive;
  }
  return label;
}

}  // namespace

ConvexParts decomposeConvex(const MeshTopology& topology, const PositionView& positions,
                            const DecompositionSettings& settings) {
  checkSettings(settings);
  const std::size_t m = topology.vertexCount();
  if (positions.size() != m) {
    throw Error(ErrorCode::InvalidArgument, "decomposeConvex: " + std::to_string(positions.size()) +
                                                " positions for a topology of " + std::to_string(m) + " vertices");
  }
  checkFinite(positions, "decomposeConvex");

  Vec3 lo = Vec3::Constant(std::numeric_limits<double>::infinity());
  Vec3 hi = -lo;
  for (std::size_t v = 0; v < m; ++v) {
    lo = lo.cwiseMin(positions[v]);
    hi = hi.cwiseMax(positions[v]);
  }
  const double diagonal = (hi - lo).norm();

  ConvexParts result;
  result.part_of.assign(m, 0);
  std::vector<Index> proxy_label;
  Proxy proxy;
  if (diagonal > 0.0) {
    if (topology.triangleCount() <= settings.max_input_triangles) {
      // Vertices at exactly the same position become one proxy vertex: HACD's hull code crashes
      // (double free) on coincident points, which the fuzzer found through duplicate vertices.
      std::vector<Index> order(m);
      for (std::size_t v = 0; v < m; ++v) order[v] = static_cast<Index>(v);
      std::sort(order.begin(), order.end(), [&](Index a, Index b) {
        const Vec3 pa = positions[a], pb = positions[b];
        if (pa.x() != pb.x()) return pa.x() < pb.x();
        if (pa.y() != pb.y()) return pa.y() < pb.y();
        if (pa.z() != pb.z()) return pa.z() < pb.z();
        return a < b;
      });
      std::vector<Index> representative(m);
      for (std::size_t k = 0; k < m; ++k)
        representative[order[k]] =
            k > 0 && positions[order[k]] == positions[order[k - 1]] ? representative[order[k - 1]] : order[k];
      proxy = buildProxy(topology, positions, [&](std::size_t v) { return std::uint64_t(representative[v]); });
    } else {
      proxy = decimate(topology, positions, settings.max_input_triangles);
    }
    const double tolerance = settings.concavity * diagonal;
    std::vector<Index> surface;  // proxy vertices that lie in a proxy triangle
    std::vector<bool> in_triangle(proxy.points.size(), false);
    for (const Triangle& t : proxy.triangles) {
      for (Index v : t) in_triangle[v] = true;
    }
    for (std::size_t v = 0; v < proxy.points.size(); ++v) {
      if (in_triangle[v]) surface.push_back(static_cast<Index>(v));
    }
    if (settings.min_parts == 1 && !surface.empty() && crossConcavity(proxy, surface, surface) <= tolerance) {
      // Exact shortcut: every union of clusters of a body within the tolerance is within it too, so
      // the merge pass would end in one part whatever HACD returned. It also skips HACD's slowest
      // case: on a closed convex surface every merge has zero concavity and HACD grows one cluster
      // a triangle at a time, recomputing a hull per neighbour (measured: 2 s for a 200-vertex
      // latitude-longitude sphere).
      proxy_label.assign(proxy.points.size(), kInvalidIndex);
      for (Index v : surface) proxy_label[v] = 0;
    } else {
      proxy_label = absorbSlivers(proxy, mergeConvexNeighbours(proxy, hacdLabels(proxy, settings), tolerance,
                                                               settings.min_parts),
                                  settings.min_parts);
    }
  }

  // Compact labels, numbered by first appearance over original vertex order (deterministic). The
  // labels are cluster numbers, which can exceed the proxy's vertex count (HACD asked for more
  // clusters than the proxy has vertices: a large min_parts).
  Index largest_label = 0;
  for (const Index l : proxy_label)
    if (l != kInvalidIndex) largest_label = std::max(largest_label, l);
  std::vector<Index> compact(static_cast<std::size_t>(largest_label) + 1, kInvalidIndex);
  std::vector<bool> labelled(m, false);
  Index parts = 0;
  for (std::size_t v = 0; v < m; ++v) {
    const Index pv = proxy.proxy_of.empty() ? kInvalidIndex : proxy.proxy_of[v];
    if (pv == kInvalidIndex || proxy_label[pv] == kInvalidIndex) continue;
    Index& c = compact[proxy_label[pv]];
    if (c == kInvalidIndex) c = parts++;
    result.part_of[v] = c;
    labelled[v] = true;
  }
  if (parts == 0) parts = 1;  // nothing labelled (no usable triangles, or a single point): one part

  // Bounding sphere of each part about its box centre; then vertices HACD never saw (isolated, or
  // whose triangles all collapsed) join the part with the nearest centre.
  auto computeParts = [&](const std::vector<bool>& use) {
    std::vector<Vec3> plo(parts, Vec3::Constant(std::numeric_limits<double>::infinity()));
    std::vector<Vec3> phi(parts, Vec3::Constant(-std::numeric_limits<double>::infinity()));
    for (std::size_t v = 0; v < m; ++v) {
      if (!use[v]) continue;
      plo[result.part_of[v]] = plo[result.part_of[v]].cwiseMin(positions[v]);
      phi[result.part_of[v]] = phi[result.part_of[v]].cwiseMax(positions[v]);
    }
    result.parts.assign(parts, ConvexPart{});
    for (Index p = 0; p < parts; ++p) {
      if (plo[p].allFinite()) result.parts[p].center = 0.5 * (plo[p] + phi[p]);
    }
    for (std::size_t v = 0; v < m; ++v) {
      if (!use[v]) continue;
      ConvexPart& part = result.parts[result.part_of[v]];
      part.radius = std::max(part.radius, (positions[v] - part.center).norm());
      ++part.vertex_count;
    }
  };
  const bool any_labelled = std::find(labelled.begin(), labelled.end(), true) != labelled.end();
  if (any_labelled) {
    computeParts(labelled);
    for (std::size_t v = 0; v < m; ++v) {
      if (labelled[v]) continue;
      Index nearest = 0;
      double best = std::numeric_limits<double>::infinity();
      for (Index p = 0; p < parts; ++p) {
        const double d = (positions[v] - result.parts[p].center).squaredNorm();
        if (d < best) {
          best = d;
          nearest = p;
        }
      }
      result.part_of[v] = nearest;
    }
  }
  computeParts(std::vector<bool>(m, true));
  return result;
}

std::size_t shadowCapBound(double part_radius, double smallest_radius) {
  if (!(part_radius > 0.0) || !(smallest_radius > 0.0) || !std::isfinite(part_radius) ||
      !std::isfinite(smallest_radius)) {
    throw Error(ErrorCode::InvalidArgument, "shadowCapBound: radii must be positive and finite, got " +
                                                std::to_string(part_radius) + " and " + std::to_string(smallest_radius));
  }
  const double s = smallest_radius / (part_radius + smallest_radius);  // sin θ
  const double c = std::sqrt(1.0 - s * s);                              // cos θ
  // A/B = 2 / (1 − cos θ), written as 2 (1 + cos θ) / sin²θ so that R ≫ r does not cancel.
  const double caps = 2.0 * (1.0 + c) / (s * s);
  // Packing efficiency of the 12-sphere kissing arrangement: 12 caps of 30° cover this share.
  const double efficiency = 6.0 * (1.0 - std::sqrt(3.0) / 2.0);
  // The tiny epsilon keeps equal sizes, exactly 12 in real arithmetic, from rounding to 11.
  const double bound = std::floor(efficiency * caps * (1.0 + 1e-12));
  constexpr double kCeiling = 1e15;  // far beyond any vertex count; keeps the cast defined
  return static_cast<std::size_t>(std::clamp(bound, 1.0, kCeiling));
}

std::vector<std::size_t> particleBudget(const std::vector<BudgetBody>& bodies) {
  std::size_t total_parts = 0;
  double smallest = std::numeric_limits<double>::infinity();
  for (std::size_t b = 0; b < bodies.size(); ++b) {
    const ConvexParts& cp = bodies[b].parts;
    if (cp.parts.empty() && bodies[b].override_count == 0) {
      throw Error(ErrorCode::InvalidArgument, "particleBudget: body " + std::to_string(b) + " has no convex parts");
    }
    total_parts += cp.parts.size();
    for (const ConvexPart& p : cp.parts) {
      if (!std::isfinite(p.radius) || p.radius < 0.0) {
        throw Error(ErrorCode::InvalidArgument, "particleBudget: body " + std::to_string(b) +
                                                    " has a part with an invalid radius");
      }
      if (p.radius > 0.0) smallest = std::min(smallest, p.radius);
    }
  }
  std::vector<std::size_t> budget(bodies.size(), 1);
  for (std::size_t b = 0; b < bodies.size(); ++b) {
    const BudgetBody& body = bodies[b];
    if (body.override_count > 0) {
      budget[b] = body.override_count;
      continue;
    }
    // Only parts of other bodies can touch one of this body's parts: same-body particles never
    // pull (docs/METHOD.md §4), so a body's own parts do not count against the cap.
    const std::size_t others = total_parts - body.parts.parts.size();
    std::size_t sum = 0;
    for (const ConvexPart& p : body.parts.parts) {
      // Point-like parts (radius 0, e.g. a single vertex) count as the smallest part; a scene of
      // point-like parts only is treated as equal sizes.
      const double r = std::isfinite(smallest) ? smallest : 1.0;
      const double radius = p.radius > 0.0 ? p.radius : r;
      sum += std::min(shadowCapBound(radius, r), others);
    }
    const std::size_t vertices = body.parts.part_of.size();
    budget[b] = std::max<std::size_t>(1, sum);
    if (vertices > 0) budget[b] = std::min(budget[b], vertices);
  }
  return budget;
}

}  // namespace psc
