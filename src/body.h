// Private: one body of a SensorWorld, its regions and its particles.
#pragma once

#include "psc/budget.h"
#include "psc/mesh.h"
#include "psc/partition.h"
#include "psc/types.h"
#include "psc/world.h"

#include <algorithm>
#include <array>
#include <cstdint>
#include <cstring>
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

/// Indices stored in the fewest bytes (1, 2 or 4) that hold the largest of them.
class PackedIndices {
 public:
  PackedIndices() = default;
  PackedIndices(std::size_t count, Index largest)
      : width_(largest <= 0xFFu ? 1 : largest <= 0xFFFFu ? 2 : 4), data_(count * width_) {}
  Index operator[](std::size_t i) const {
    if (width_ == 1) return data_[i];
    if (width_ == 2) {
      std::uint16_t x;
      std::memcpy(&x, data_.data() + 2 * i, 2);
      return x;
    }
    Index x;
    std::memcpy(&x, data_.data() + 4 * i, 4);
    return x;
  }
  void set(std::size_t i, Index x) {
    if (width_ == 1) {
      data_[i] = static_cast<std::uint8_t>(x);
    } else if (width_ == 2) {
      const auto y = static_cast<std::uint16_t>(x);
      std::memcpy(data_.data() + 2 * i, &y, 2);
    } else {
      std::memcpy(data_.data() + 4 * i, &x, 4);
    }
  }
  unsigned width() const { return width_; }
  std::size_t size() const { return data_.size() / width_; }
  const std::uint8_t* data() const { return data_.data(); }
  std::size_t bytes() const { return data_.capacity(); }

 private:
  unsigned width_ = 1;
  std::vector<std::uint8_t> data_;
};

/// Per vertex, the chunks other than its own whose owned triangles hold it, ascending. On the
/// benchmark's meshes about half the vertices have none, four in ten one, one in ten two and under
/// one in a hundred three. Two slots per vertex (none() where empty, in the fewest bytes that hold
/// the chunk count) and the rare rest in `extra`: the refit then updates two boxes per vertex
/// without a branch on the count (its loop over rows of 0, 1 or 2 entries was mispredicted on
/// about half the vertices), in fewer bytes than rows with offsets.
class ForeignChunks {
 public:
  ForeignChunks() = default;
  /// From (vertex, chunk) pairs in any order (duplicates come once); `chunks` is the chunk count,
  /// the value of an empty slot.
  ForeignChunks(std::size_t vertices, Index chunks, const std::vector<std::pair<Index, Index>>& pairs);
  Index none() const { return none_; }
  /// The two slots of vertex v: its first two foreign chunks, or none().
  Index first(std::size_t v) const { return slots_[2 * v]; }
  Index second(std::size_t v) const { return slots_[2 * v + 1]; }
  /// The slots as stored: 2 per vertex of slotWidth() bytes each.
  const std::uint8_t* slotData() const { return slots_.data(); }
  unsigned slotWidth() const { return slots_.width(); }
  /// (vertex, chunk) beyond each vertex's two slots, by vertex then chunk.
  const std::vector<std::pair<Index, Index>>& extra() const { return extra_; }
  /// f(chunk) for each foreign chunk of v, ascending.
  template <class F>
  void forEach(Index v, F&& f) const {
    const Index a = first(v), b = second(v);
    if (a == none_) return;
    f(a);
    if (b == none_) return;
    f(b);
    auto it = std::lower_bound(extra_.begin(), extra_.end(), std::make_pair(v, Index{0}));
    for (; it != extra_.end() && it->first == v; ++it) f(it->second);
  }
  std::size_t bytes() const { return slots_.bytes() + extra_.capacity() * sizeof(extra_[0]); }

 private:
  PackedIndices slots_;
  std::vector<std::pair<Index, Index>> extra_;
  Index none_ = 0;
};

/// [beyond] The bounds layer under the regions: each region cut into compact chunks of at most
/// `chunk_vertices` vertices (median splits along the longest axis). Every triangle belongs to
/// exactly one chunk (that of its lowest vertex index), so each (vertex, triangle) pair belongs
/// to exactly one (chunk, chunk) pair and candidate pairs come out unique without sorting.
///
/// The chunks are also the body's runtime mesh, so that the full MeshTopology (one-ring and
/// vertex-triangle lists, components) need not stay alive after partitioning: each chunk keeps a
/// table of the vertices its triangles use, its own vertices first, then its foreign ones (each
/// part ascending), and its triangles as positions in that table. The triangles are stored once;
/// a vertex's one ring comes from the triangles of its own and foreign chunks (forEachTriangleOf).
/// A chunk's triangles are numbered close together in most meshes: their mesh indices are kept as
/// offsets from a base, modulo the triangle count, so that a chunk across the seam where a grid's
/// numbering wraps around (index 0 beside the last) is close too. Both are PackedIndices: 1 byte
/// per corner and 2 per triangle index in the benchmark's meshes (docs/DECISIONS.md, "Midphase
/// memory").
struct ChunkLists {
  std::vector<Index> table;           ///< the chunks' vertex tables, one after the other
  std::vector<Index> table_begin;     ///< chunk c's table is [table_begin[c], table_begin[c+1])
  std::vector<Index> own_end;         ///< its own vertices are [table_begin[c], own_end[c])
  std::vector<Index> triangle_begin;  ///< chunk c owns the triangles [triangle_begin[c], triangle_begin[c+1])
  std::vector<Index> triangle_base;   ///< per chunk, the mesh index its triangles' offsets start from
  PackedIndices triangle_offset;      ///< per owned triangle, (mesh index − base) mod triangle count
  PackedIndices corners;              ///< per owned triangle, its 3 vertices as positions in the table
  std::vector<Index> region_begin;  ///< chunks of region r are [region_begin[r], region_begin[r+1])
  std::vector<Index> region_of;     ///< region of each chunk
  /// The refit streams through the vertices in index order (the positions' memory order): per
  /// vertex, the chunk that owns it (foreign.none(), the chunk count, for a vertex of no region),
  /// in the fewest bytes that hold the chunk count, as `foreign`'s slots: 1 byte a vertex below
  /// 256 chunks, 2 below 65,536. (A vertex on no triangle has a region, the partition's nearest,
  /// and so a chunk.)
  PackedIndices owner;
  ForeignChunks foreign;            ///< per vertex, the other chunks whose owned triangles it is in
  /// The vertices with a chunk that are on no triangle, ascending (a volumetric body's inner
  /// nodes): the self motion term's mean displacement leaves them out (psc::selfMotion). Empty
  /// for a surface mesh.
  std::vector<Index> loose;

  std::size_t count() const { return table_begin.size() - 1; }
  std::size_t vertexCount() const { return owner.size(); }
  /// The chunk owning vertex v (kInvalidIndex: in no chunk).
  Index chunkOf(std::size_t v) const {
    const Index c = owner[v];
    return c == foreign.none() ? kInvalidIndex : c;
  }
  /// Own vertices of chunk c, ascending.
  IndexRange vertices(Index c) const { return {table.data() + table_begin[c], table.data() + own_end[c]}; }
  std::size_t triangleCount(Index c) const { return triangle_begin[c + 1] - triangle_begin[c]; }
  /// Owned triangle k (triangle_begin[c] ≤ k < triangle_begin[c+1]) of chunk c: its mesh index,
  /// and its vertices.
  Index triangleId(Index c, std::size_t k) const {
    const Index base = triangle_base[c], offset = triangle_offset[k], total = triangle_begin.back();
    return offset < total - base ? base + offset : offset - (total - base);
  }
  Triangle triangle(Index c, std::size_t k) const {
    const Index* t = table.data() + table_begin[c];
    return {t[corners[3 * k]], t[corners[3 * k + 1]], t[corners[3 * k + 2]]};
  }
  /// f(t, triangle) for every triangle t that holds vertex v: those owned by v's chunk and by its
  /// foreign chunks. A triangle holding v twice (degenerate) comes once.
  template <class F>
  void forEachTriangleOf(Index v, F&& f) const {
    const auto scan = [&](Index c, Index at) {
      // The search is the particles' inner loop: one-byte corners are compared in place.
      const std::uint8_t* bytes = corners.width() == 1 ? corners.data() : nullptr;
      for (std::size_t k = triangle_begin[c]; k < triangle_begin[c + 1]; ++k)
        if (bytes != nullptr ? bytes[3 * k] == at || bytes[3 * k + 1] == at || bytes[3 * k + 2] == at
                             : corners[3 * k] == at || corners[3 * k + 1] == at || corners[3 * k + 2] == at)
          f(triangleId(c, k), triangle(c, k));
    };
    const Index own = chunkOf(v);
    if (own == kInvalidIndex) return;
    const Index* t = table.data();
    scan(own, static_cast<Index>(std::lower_bound(t + table_begin[own], t + own_end[own], v) - (t + table_begin[own])));
    foreign.forEach(v, [&](Index c) {
      scan(c, static_cast<Index>(std::lower_bound(t + own_end[c], t + table_begin[c + 1], v) - (t + table_begin[c])));
    });
  }
  /// The mesh's triangles in their original order (to rebuild the full topology).
  std::vector<Triangle> meshTriangles() const;
  /// The partition's region of every vertex: that of its chunk.
  std::vector<Index> regionOfVertices() const;
  std::size_t bytes() const {
    return (table.capacity() + table_begin.capacity() + own_end.capacity() + triangle_begin.capacity() +
            triangle_base.capacity() + region_begin.capacity() + region_of.capacity() + loose.capacity()) *
               sizeof(Index) +
           owner.bytes() + triangle_offset.bytes() + corners.bytes() + foreign.bytes();
  }
};

ChunkLists buildChunks(const MeshTopology& topology, const PositionView& positions,
                       const std::vector<Index>& region_of, std::size_t regions, std::size_t chunk_vertices);

/// Shape figures measured during a refit (Body::shape): what the repartition check needs.
struct ShapeFigures {
  std::vector<double> region_area;  ///< area of the triangles owned by each region's chunks (estimated
                                    ///< from a sample of them by a sampled measure: refitBounds)
  std::vector<double> chunk_area;   ///< with a full measure, each chunk's (empty otherwise)
  double max_edge = 0.0;            ///< longest triangle edge
};

/// Axis-aligned box with the largest vertex motion inside it.
struct MotionBox {
  Vec3 lo = Vec3::Zero();
  Vec3 hi = Vec3::Zero();
  double motion = 0.0;
};

/// [beyond] A chunk's box of its own vertices alone, without the corners its triangles borrow from
/// its neighbours (MotionBox holds both), in the positions' single precision.
struct OwnBox {
  std::array<float, 3> lo, hi;
};

/// The order of StepResult::flagged: (body_a, region_a, body_b, region_b).
inline bool flaggedLess(const FlaggedPair& a, const FlaggedPair& b) {
  if (a.body_a != b.body_a) return a.body_a < b.body_a;
  if (a.region_a != b.region_a) return a.region_a < b.region_a;
  if (a.body_b != b.body_b) return a.body_b < b.body_b;
  return a.region_b < b.region_b;
}

/// A self-colliding body's rest shape: each vertex's position when self-collision was switched on,
/// kept in the precision the positions came in, so every value is the one given: single for
/// Bullet's nodes (12 bytes a vertex instead of 24), double otherwise. Read as Vec3.
class RestShape {
 public:
  RestShape() = default;
  explicit RestShape(const PositionView& positions) : size_(positions.size()) {
    if (positions.scalar() == PositionView::Scalar::Float32) {
      // The view widens each float to double exactly, so the narrowing back is exact too.
      single_.resize(3 * size_);
      for (std::size_t v = 0; v < size_; ++v) {
        const Vec3 p = positions[v];
        for (int j = 0; j < 3; ++j) single_[3 * v + j] = static_cast<float>(p[j]);
      }
    } else {
      double_.resize(size_);
      for (std::size_t v = 0; v < size_; ++v) double_[v] = positions[v];
    }
  }
  bool empty() const { return size_ == 0; }
  std::size_t size() const { return size_; }
  Vec3 operator[](std::size_t v) const {
    if (!single_.empty()) {
      const float* p = single_.data() + 3 * v;
      return {p[0], p[1], p[2]};
    }
    return double_[v];
  }
  /// The coordinates in single precision, three a vertex; null when they are kept in double.
  const float* single() const { return single_.empty() ? nullptr : single_.data(); }
  std::size_t bytes() const { return single_.capacity() * sizeof(float) + double_.capacity() * sizeof(Vec3); }

 private:
  std::vector<float> single_;
  std::vector<Vec3> double_;
  std::size_t size_ = 0;
};

/// [beyond] The rest-shape bound of self-collision (docs/METHOD.md §6.3), riding on the refit.
/// Per region r a rotation R_r; the refit's pass puts each vertex's y = x − R_r·rest into a box
/// per chunk (its own chunk and the chunks whose triangles it is in, each with its chunk's region's
/// rotation), so that every rigid motion p ↦ R_r p + k deviates from a chunk's vertices by at most
/// the distance from k to the farthest corner of the chunk's y-box. The same pass sums what the
/// next step's R_r needs (the rotation that best carries the region's rest shape onto its current
/// vertices). Nothing of it is read per vertex after the pass.
struct RestFit {
  // Set-up (rest shape and chunks; made with the object).
  std::vector<double> region_count;       ///< own vertices of each region
  std::vector<Vec3> region_rest_mean;     ///< their rest centroid
  std::vector<Vec3> chunk_rest_center;    ///< the rest sphere of each chunk's vertex table
  std::vector<double> chunk_rest_radius;
  std::vector<Vec3> region_rest_center;   ///< the rest sphere of each region's tables
  std::vector<double> region_rest_radius;
  // Carried from one step to the next.
  std::vector<Eigen::Matrix3d> fit;       ///< per region, the last fit (empty before the first)
  std::vector<Eigen::Matrix3d> next_rot;  ///< per region, the rotation the next pass uses
  // This step's (valid when `filled`).
  bool filled = false;
  std::vector<Eigen::Matrix3d> rot;  ///< per region, the rotation of this step's y-boxes
  std::vector<Vec3> chunk_lo, chunk_hi;
  std::vector<Vec3> chunk_center;    ///< centre of each chunk's y-box
  std::vector<double> chunk_half;    ///< its half diagonal
  std::vector<Vec3> region_center;   ///< the same for the union of a region's chunks
  std::vector<double> region_half;
  std::vector<Vec3> region_sum_x;           ///< Σ x over the region's own vertices
  std::vector<Eigen::Matrix3d> region_xr;   ///< Σ x restᵀ over them
  // The self motion term (psc::selfMotion): a vertex's displacement this step against the body's
  // mean displacement `mean_motion`, bounded per chunk from the box of its own vertices'
  // displacements, never above the chunk's largest displacement (chunk_box[c].motion).
  Vec3 sum_motion = Vec3::Zero();
  double moved = 0.0;                        ///< vertices in sum_motion
  std::vector<Vec3> move_lo, move_hi;        ///< per chunk, the box of its own vertices' displacements
  Vec3 mean_motion = Vec3::Zero();
  std::vector<double> chunk_self_motion;     ///< largest selfMotion of a chunk's own vertices (bound)
  /// What y = x − R·rest's rounding can move a deviation by: y is made at the magnitude of the
  /// positions and the rest shape (a few units in the last place of each), far above the deviations
  /// when a body lies far from the origin. Every rest-shape test leaves this much more room.
  double rounding = 0.0;
  double rest_magnitude = 0.0;               ///< set-up: the largest |rest| of any vertex (bound)
  std::vector<double> region_self_motion;    ///< the same over a region's chunks
  std::size_t bytes() const {
    const std::size_t regions = region_count.capacity(), chunks = chunk_rest_radius.capacity();
    return regions * (3 * sizeof(double) + 4 * sizeof(Vec3) + 4 * sizeof(Eigen::Matrix3d)) +
           chunks * (3 * sizeof(double) + 6 * sizeof(Vec3));
  }
};

struct Body {
  BodyId id = kInvalidBody;
  std::string name;
  /// The full topology (one rings, vertex triangles, components) is a setup structure: built by
  /// addBody and kept until the body is partitioned, then dropped unless the settings need it
  /// every step (thesis mode, the four-direction walk). Partitioning again and inspection rebuild
  /// it from the chunks (fullTopology) until the next step.
  std::optional<MeshTopology> topology;
  std::size_t vertex_count = 0;
  PositionView positions;
  PositionView previous;
  double margin = 0.0;
  std::size_t particle_override = 0;
  bool deformable = true;
  std::shared_ptr<const ConvexParts> parts;
  /// Self-collision: on when `rest` holds the rest shape (SensorWorld::setSelfCollision).
  RestShape rest;
  double rest_mean_edge = 0.0;  ///< mean edge length of `rest` (the self contact radius's base)
  bool selfCollides() const { return !rest.empty(); }
  /// Only for a self-colliding body (made by its first refit; dropped whenever `rest` or the
  /// chunks change), so that the other bodies do not pay its size.
  std::unique_ptr<RestFit> rest_fit;
  MeshReport report;
  std::size_t vertices_in_triangles = 0;

  // Partition state; valid when `partitioned`.
  bool partitioned = false;
  /// Made by SensorWorld::replaceMesh and not partitioned since: its first partition is a
  /// repartition of the body (repartitions, StepStats::repartitions).
  bool replaced = false;
  std::size_t budget = 0;
  Partition partition;                 ///< its region_of is dropped and rebuilt like `topology`
  RegionLists regions;                 ///< built only for Flagging::Sensors (thesis candidate sets)
  std::vector<Index> particle_vertex;  ///< one per region
  double mean_edge = 0.0;              ///< at (re)partitioning: μ's geometric base
  double max_edge = 0.0;               ///< at (re)partitioning: the stretch trigger's base
  double area_star = 0.0;              ///< A*: largest region area at (re)partitioning
  /// Each chunk's area at (re)partitioning: the reference of the checks' sampled region areas.
  std::vector<double> chunk_area_ref;
  std::size_t repartitions = 0;
  std::uint64_t partition_number = 0;  ///< unique in the world for each (re)partitioning
  int steps_since_check = 0;

  // Bounds layer (Flagging::SensorsAndBounds), refit every step.
  ChunkLists chunks;
  std::vector<MotionBox> chunk_box;
  /// Each chunk's own vertices' box, when the refit's packed single-precision pass made it (empty
  /// otherwise): where the candidate stage asks whether a chunk's vertices can reach another body's
  /// chunk, it then needs no vertex (Collector::verticesReach).
  std::vector<OwnBox> chunk_own;
  std::vector<MotionBox> region_box;
  MotionBox body_box;
  ShapeFigures shape;  ///< filled by refitBounds with a measure
  /// SensorWorld::refitNow refit the boxes for the coming step(), which then skips the body's refit;
  /// anything that changes what the refit reads (positions, self-collision) clears it.
  bool refit_ahead = false;

  std::string label() const { return name.empty() ? "body #" + std::to_string(id) : "body '" + name + "'"; }
  std::size_t regionCount() const { return particle_vertex.size(); }
  double vertexMotion(Index v) const { return previous.empty() ? 0.0 : (positions[v] - previous[v]).norm(); }

  /// The full topology, rebuilt from the chunks if it was dropped (same triangles, same order).
  const MeshTopology& fullTopology() {
    if (!topology) topology.emplace(chunks.meshTriangles(), vertex_count);
    return *topology;
  }
  /// The partition with its region_of, rebuilt from the chunks if it was dropped (once partitioned).
  const Partition& fullPartition() {
    if (partition.region_of.empty()) partition.region_of = chunks.regionOfVertices();
    return partition;
  }
  /// Drops what only (re)partitioning and inspection read; both rebuild it from the chunks.
  void dropSetup() {
    topology.reset();
    partition.region_of = std::vector<Index>{};
  }
};

}  // namespace psc::detail
