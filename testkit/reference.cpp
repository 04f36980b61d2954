#include "psc/testkit/reference.h"

#include <algorithm>

namespace psc::testkit {
namespace {

/// Closest point of segment ab to p (a itself when the segment has no length).
Vec3 closestPointOnSegment(const Vec3& p, const Vec3& a, const Vec3& b) {
  const Vec3 ab = b - a;
  const double len2 = ab.squaredNorm();
  const double t = len2 > 0.0 ? std::clamp((p - a).dot(ab) / len2, 0.0, 1.0) : 0.0;
  return a + t * ab;
}

}  // namespace

Vec3 closestPointOnTriangle(const Vec3& p, const Vec3& a, const Vec3& b, const Vec3& c) {
  const Vec3 ab = b - a, ac = c - a;
  const double n2 = ab.cross(ac).squaredNorm();
  if (!(n2 > 1e-24 * ab.squaredNorm() * ac.squaredNorm()) || n2 == 0.0) {
    const Vec3 on_edge[3] = {closestPointOnSegment(p, a, b), closestPointOnSegment(p, b, c),
                             closestPointOnSegment(p, c, a)};
    return *std::min_element(std::begin(on_edge), std::end(on_edge), [&](const Vec3& x, const Vec3& y) {
      return (p - x).squaredNorm() < (p - y).squaredNorm();
    });
  }
  const Vec3 ap = p - a;
  const double d1 = ab.dot(ap), d2 = ac.dot(ap);
  if (d1 <= 0.0 && d2 <= 0.0) return a;
  const Vec3 bp = p - b;
  const double d3 = ab.dot(bp), d4 = ac.dot(bp);
  if (d3 >= 0.0 && d4 <= d3) return b;
  const double vc = d1 * d4 - d3 * d2;
  if (vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0) return a + (d1 / (d1 - d3)) * ab;
  const Vec3 cp = p - c;
  const double d5 = ab.dot(cp), d6 = ac.dot(cp);
  if (d6 >= 0.0 && d5 <= d6) return c;
  const double vb = d5 * d2 - d1 * d6;
  if (vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0) return a + (d2 / (d2 - d6)) * ac;
  const double va = d3 * d6 - d5 * d4;
  if (va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0) return b + ((d4 - d3) / ((d4 - d3) + (d5 - d6))) * (c - b);
  const double denom = 1.0 / (va + vb + vc);
  return a + ab * (vb * denom) + ac * (vc * denom);
}

double pointTriangleDistanceSquared(const Vec3& p, const Vec3& a, const Vec3& b, const Vec3& c) {
  return (p - closestPointOnTriangle(p, a, b, c)).squaredNorm();
}

double pointTriangleDistance(const Vec3& p, const Vec3& a, const Vec3& b, const Vec3& c) {
  return (p - closestPointOnTriangle(p, a, b, c)).norm();
}

bool selfPairExcluded(Index v, const Triangle& t, const std::vector<Vec3>& rest, double self_radius,
                      double rest_exclusion) {
  if (t[0] == v || t[1] == v || t[2] == v) return true;
  return pointTriangleDistance(rest[v], rest[t[0]], rest[t[1]], rest[t[2]]) < rest_exclusion * self_radius;
}

namespace {
/// in_ring[u]: u lies outside `region` and shares a triangle with a vertex inside it.
std::vector<char> ringOf(const MeshTopology& topology, const std::vector<Index>& region_of, Index region) {
  std::vector<char> in_ring(topology.vertexCount(), 0);
  for (Index t = 0; t < topology.triangleCount(); ++t) {
    const Triangle& tri = topology.triangle(t);
    const bool touches = region_of[tri[0]] == region || region_of[tri[1]] == region || region_of[tri[2]] == region;
    if (touches)
      for (Index u : tri)
        if (region_of[u] != region) in_ring[u] = 1;
  }
  return in_ring;
}
}  // namespace

RegionSets regionSets(const MeshTopology& vertex_topology, const std::vector<Index>& vertex_region_of,
                      Index vertex_region, const MeshTopology& triangle_topology,
                      const std::vector<Index>& triangle_region_of, Index triangle_region, bool one_ring) {
  RegionSets out;
  const std::vector<char> vring = ringOf(vertex_topology, vertex_region_of, vertex_region);
  for (Index v = 0; v < vertex_topology.vertexCount(); ++v)
    if (vertex_region_of[v] == vertex_region || (one_ring && vring[v])) out.vertices.push_back(v);
  const std::vector<char> tring = ringOf(triangle_topology, triangle_region_of, triangle_region);
  for (Index t = 0; t < triangle_topology.triangleCount(); ++t) {
    bool in = false;
    for (Index u : triangle_topology.triangle(t)) in = in || triangle_region_of[u] == triangle_region || (one_ring && tring[u]);
    if (in) out.triangles.push_back(t);
  }
  return out;
}

RegionSets regionSets(const SensorWorld& world, const FlaggedPair& pair, BodyId vertex_body) {
  const bool a_side = vertex_body == pair.body_a;
  const BodyId triangle_body = a_side ? pair.body_b : pair.body_a;
  return regionSets(world.topology(vertex_body), world.partition(vertex_body).region_of,
                    a_side ? pair.region_a : pair.region_b, world.topology(triangle_body),
                    world.partition(triangle_body).region_of, a_side ? pair.region_b : pair.region_a,
                    world.settings().one_ring);
}

std::vector<std::pair<Index, Index>> bruteContacts(const TriMesh& vm, const TriMesh& tm, double radius) {
  std::vector<std::pair<Index, Index>> out;
  forEachContact(vm.vertices, tm.vertices, tm.triangles, [&](Index) { return radius; },
                 [&](Index v, Index t, double) { out.emplace_back(v, t); });
  return out;
}

}  // namespace psc::testkit
