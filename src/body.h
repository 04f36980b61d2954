// Private: one body of a SensorWorld, its regions and its particles.
#pragma once

#include "psc/budget.h"
#include "psc/mesh.h"
#include "psc/partition.h"
#include "psc/types.h"
#include "psc/world.h"

#include <memory>
#include <optional>
#include <string>
#include <vector>

namespace psc::detail {

/// Per-region index lists derived from a partition (the thesis's regions plus the one-vertex ring
/// that §3.5's exact check extends them by).
struct RegionLists {
  IndexRows vertices;        ///< vertices of each region, ascending
  IndexRows ring;            ///< vertices adjacent to the region but outside it, ascending
  IndexRows triangles;       ///< triangles with at least one vertex in the region, ascending
  IndexRows ring_triangles;  ///< triangles touching the ring but not the region, ascending
  std::size_t bytes() const { return vertices.bytes() + ring.bytes() + triangles.bytes() + ring_triangles.bytes(); }
};

RegionLists buildRegionLists(const MeshTopology& topology, const std::vector<Index>& region_of, std::size_t regions);

/// [beyond] The bounds layer under the regions: each region cut into compact chunks of at most
/// `chunk_vertices` vertices (median splits along the longest axis). Every triangle belongs to
/// exactly one chunk (that of its lowest vertex index), so each (vertex, triangle) pair belongs
/// to exactly one (chunk, chunk) pair and candidate pairs come out unique without sorting.
struct ChunkLists {
  IndexRows vertices;         ///< own vertices of each chunk
  IndexRows triangles;        ///< triangles owned by each chunk
  std::vector<Index> region_begin;  ///< chunks of region r are [region_begin[r], region_begin[r+1])
  std::vector<Index> region_of;     ///< region of each chunk
  /// The refit streams through the vertices in index order (the positions' memory order):
  std::vector<Index> chunk_of;      ///< chunk owning each vertex (kInvalidIndex: in no triangle)
  IndexRows foreign_of;             ///< per vertex, the other chunks whose owned triangles it is in
  std::size_t count() const { return vertices.rows(); }
  std::size_t bytes() const {
    return vertices.bytes() + triangles.bytes() + foreign_of.bytes() +
           (region_begin.capacity() + region_of.capacity() + chunk_of.capacity()) * sizeof(Index);
  }
};

ChunkLists buildChunks(const MeshTopology& topology, const PositionView& positions,
                       const std::vector<Index>& region_of, std::size_t regions, std::size_t chunk_vertices);

/// Shape figures measured during a refit (Body::shape): what the repartition check needs.
struct ShapeFigures {
  std::vector<double> region_area;  ///< area of the triangles owned by each region's chunks
  double max_edge = 0.0;            ///< longest triangle edge
};

/// Axis-aligned box with the largest vertex motion inside it.
struct MotionBox {
  Vec3 lo = Vec3::Zero();
  Vec3 hi = Vec3::Zero();
  double motion = 0.0;
};

/// The order of StepResult::flagged: (body_a, region_a, body_b, region_b).
inline bool flaggedLess(const FlaggedPair& a, const FlaggedPair& b) {
  if (a.body_a != b.body_a) return a.body_a < b.body_a;
  if (a.region_a != b.region_a) return a.region_a < b.region_a;
  if (a.body_b != b.body_b) return a.body_b < b.body_b;
  return a.region_b < b.region_b;
}

struct Body {
  BodyId id = kInvalidBody;
  std::string name;
  std::optional<MeshTopology> topology;
  PositionView positions;
  PositionView previous;
  double margin = 0.0;
  std::size_t particle_override = 0;
  bool deformable = true;
  std::shared_ptr<const ConvexParts> parts;
  /// Self-collision: on when `rest` holds the rest shape (SensorWorld::setSelfCollision).
  std::vector<Vec3> rest;
  bool selfCollides() const { return !rest.empty(); }
  MeshReport report;
  std::size_t vertices_in_triangles = 0;

  // Partition state; valid when `partitioned`.
  bool partitioned = false;
  std::size_t budget = 0;
  Partition partition;
  RegionLists regions;                 ///< built only for Flagging::Sensors (thesis candidate sets)
  std::vector<Index> particle_vertex;  ///< one per region
  double mean_edge = 0.0;              ///< at (re)partitioning: μ's geometric base
  double max_edge = 0.0;               ///< at (re)partitioning: the stretch trigger's base
  double area_star = 0.0;              ///< A*: largest region area at (re)partitioning
  std::size_t repartitions = 0;
  int steps_since_check = 0;

  // Bounds layer (Flagging::SensorsAndBounds), refit every step.
  ChunkLists chunks;
  std::vector<MotionBox> chunk_box;
  std::vector<MotionBox> region_box;
  MotionBox body_box;
  ShapeFigures shape;  ///< filled by refitBounds(b, true)

  std::string label() const { return name.empty() ? "body #" + std::to_string(id) : "body '" + name + "'"; }
  std::size_t regionCount() const { return particle_vertex.size(); }
  double vertexMotion(Index v) const { return previous.empty() ? 0.0 : (positions[v] - previous[v]).norm(); }
};

}  // namespace psc::detail
