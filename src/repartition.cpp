#include "psc/repartition.h"

#include "psc/error.h"

#include <cmath>

namespace psc {

std::vector<double> regionAreasTrue(const MeshTopology& topology, const PositionView& positions,
                                    const Partition& partition) {
  std::vector<double> area(partition.regionCount(), 0.0);
  for (std::size_t t = 0; t < topology.triangleCount(); ++t) {
    const double third = doubleArea(topology, positions, t) / 6.0;
    for (Index v : topology.triangle(t)) area[partition.region_of[v]] += third;
  }
  return area;
}

namespace {

// Sum of edge lengths walked from `start` along direction d (thesis §3.6): each hop goes to the
// neighbour at the smallest angle to d; the walk ends where that neighbour lies outside the region
// or no neighbour lies ahead.
double walkLength(const MeshTopology& topology, const PositionView& positions, const Partition& partition, Index start,
                  const Vec3& d) {
  const Index region = partition.region_of[start];
  double length = 0.0;
  Index cur = start;
  for (std::size_t hop = 0; hop < topology.vertexCount(); ++hop) {
    const Vec3 p = positions[cur];
    double best_cos = 0.0;
    Index best = kInvalidIndex;
    for (Index u : topology.neighbors(cur)) {
      const Vec3 e = positions[u] - p;
      const double len = e.norm();
      if (len <= 0.0) continue;
      const double c = e.dot(d) / len;
      if (c > best_cos) {
        best_cos = c;
        best = u;
      }
    }
    if (best == kInvalidIndex || partition.region_of[best] != region) break;
    length += (positions[best] - p).norm();
    cur = best;
  }
  return length;
}

}  // namespace

double regionAreaWalk(const MeshTopology& topology, const PositionView& positions, const Partition& partition,
                      Index start) {
  Vec3 n = Vec3::Zero();
  for (Index t : topology.vertexTriangles(start)) {
    const Triangle& tri = topology.triangle(t);
    const Vec3 a = positions[tri[0]];
    n += (positions[tri[1]] - a).cross(positions[tri[2]] - a);
  }
  if (n.norm() == 0.0) return 0.0;
  n.normalize();
  // Tangent frame: X from the world axis least aligned with the normal, so the frame is stable
  // under small deformation and identical for identical input.
  Vec3 axis = Vec3::UnitX();
  if (std::abs(n.y()) < std::abs(n[0]) && std::abs(n.y()) <= std::abs(n.z())) axis = Vec3::UnitY();
  else if (std::abs(n.z()) < std::abs(n[0]) && std::abs(n.z()) < std::abs(n.y())) axis = Vec3::UnitZ();
  const Vec3 x = (axis - axis.dot(n) * n).normalized();
  const Vec3 y = n.cross(x);
  const double lx = walkLength(topology, positions, partition, start, x) +
                    walkLength(topology, positions, partition, start, -x);
  const double ly = walkLength(topology, positions, partition, start, y) +
                    walkLength(topology, positions, partition, start, -y);
  return lx * ly;
}

std::vector<double> regionAreas(const MeshTopology& topology, const PositionView& positions, const Partition& partition,
                                const std::vector<Index>& particle_vertices, AreaEstimator estimator) {
  if (estimator == AreaEstimator::TrueArea) return regionAreasTrue(topology, positions, partition);
  if (particle_vertices.size() != partition.regionCount())
    throw Error(ErrorCode::InvalidArgument, "regionAreas: one particle vertex per region is needed");
  std::vector<double> area(partition.regionCount());
  for (std::size_t r = 0; r < area.size(); ++r)
    area[r] = regionAreaWalk(topology, positions, partition, particle_vertices[r]);
  return area;
}

}  // namespace psc
