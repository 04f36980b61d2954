// The surface mesh as the core sees it: a topology built once (triangles, one-ring adjacency,
// edges, connected components) and positions read in place through a strided view, so that a
// step touches only the vertices it needs (docs/METHOD.md §1).
#pragma once

#include "psc/types.h"

#include <string>
#include <vector>

namespace psc {

/// Read-only strided view of vertex positions owned by someone else (e.g. btSoftBody::m_nodes:
/// `data` = &nodes[0].m_x, `stride_bytes` = sizeof(btSoftBody::Node)). Nothing is copied; the
/// owner keeps the memory alive and valid while the view is in use.
class PositionView {
 public:
  enum class Scalar { Float32, Float64 };

  PositionView() = default;
  PositionView(const float* xyz, std::size_t count, std::size_t stride_bytes = 3 * sizeof(float))
      : data_(xyz), count_(count), stride_(stride_bytes), scalar_(Scalar::Float32) {}
  PositionView(const double* xyz, std::size_t count, std::size_t stride_bytes = 3 * sizeof(double))
      : data_(xyz), count_(count), stride_(stride_bytes), scalar_(Scalar::Float64) {}
  /// A view over a contiguous vector of Vec3 (Eigen::Vector3d is three packed doubles).
  static PositionView of(const std::vector<Vec3>& points) {
    return PositionView(points.empty() ? nullptr : points[0].data(), points.size(), sizeof(Vec3));
  }

  Vec3 operator[](std::size_t i) const {
    const char* p = static_cast<const char*>(data_) + i * stride_;
    if (scalar_ == Scalar::Float32) {
      const float* f = reinterpret_cast<const float*>(p);
      return {f[0], f[1], f[2]};
    }
    const double* d = reinterpret_cast<const double*>(p);
    return {d[0], d[1], d[2]};
  }
  std::size_t size() const { return count_; }
  bool empty() const { return count_ == 0 || data_ == nullptr; }
  Scalar scalar() const { return scalar_; }
  const void* data() const { return data_; }
  std::size_t strideBytes() const { return stride_; }

 private:
  const void* data_ = nullptr;
  std::size_t count_ = 0;
  std::size_t stride_ = 0;
  Scalar scalar_ = Scalar::Float64;
};

/// What validation found that is legal but worth knowing. Errors (NaN, out-of-range index, no
/// triangles) throw psc::Error instead; everything here is accepted and handled.
struct MeshReport {
  std::size_t degenerate_triangles = 0;   ///< zero area, or a repeated vertex index
  std::size_t sliver_triangles = 0;       ///< smallest altitude < 1e-3 × longest edge
  std::size_t duplicate_vertices = 0;     ///< same position as an earlier vertex (exactly)
  std::size_t isolated_vertices = 0;      ///< in no triangle: no region can reach them by hops
  std::size_t non_manifold_edges = 0;     ///< edges shared by more than two triangles
  std::size_t boundary_edges = 0;         ///< edges of one triangle only (open surfaces)
  std::size_t inconsistent_winding_edges = 0;  ///< interior edges traversed the same way twice
  std::size_t components = 0;             ///< connected pieces (over triangles)
  Index first_degenerate_triangle = kInvalidIndex;
  std::string summary() const;            ///< one line, for logs
};

/// Connectivity of a triangle mesh, computed once per topology. Immutable afterwards.
class MeshTopology {
 public:
  /// Throws psc::Error(InvalidMesh) naming the triangle and index when an index is out of range,
  /// or when there are no vertices or no triangles.
  MeshTopology(std::vector<Triangle> triangles, std::size_t vertex_count);

  std::size_t vertexCount() const { return vertex_count_; }
  std::size_t triangleCount() const { return triangles_.size(); }
  const std::vector<Triangle>& triangles() const { return triangles_; }
  const Triangle& triangle(std::size_t t) const { return triangles_[t]; }

  /// One-ring neighbours of v (sorted ascending, no duplicates, v itself excluded).
  IndexRange neighbors(Index v) const { return adjacency_.row(v); }
  /// Triangles incident to v (sorted ascending).
  IndexRange vertexTriangles(Index v) const { return vertex_triangles_.row(v); }
  /// Unique undirected edges (a < b), sorted; built on each call from the adjacency.
  std::vector<std::array<Index, 2>> edges() const;
  std::size_t edgeCount() const { return adjacency_.items.size() / 2; }

  /// Connected component of each vertex (over shared triangles); isolated vertices get their own.
  const std::vector<Index>& componentOf() const { return component_; }
  std::size_t componentCount() const { return component_count_; }

  /// Bytes held by this topology (for memory reports).
  std::size_t bytes() const;

 private:
  std::vector<Triangle> triangles_;
  std::size_t vertex_count_ = 0;
  IndexRows adjacency_;
  IndexRows vertex_triangles_;
  std::vector<Index> component_;
  std::size_t component_count_ = 0;
};

/// Checks positions against a topology. Throws psc::Error(InvalidMesh) naming the first vertex
/// with a NaN, infinite or out-of-range (> kMaxCoordinate) coordinate, or a view whose size
/// differs from the vertex count.
/// `what` prefixes the message (e.g. the body's name). Returns the legal-but-notable findings.
MeshReport validate(const MeshTopology& topology, const PositionView& positions,
                    const std::string& what = "mesh");

/// Largest accepted coordinate magnitude (length units). Beyond it, squared lengths and squared
/// areas (length⁴) computed in double would overflow; no scene needs it, since a mesh of unit size
/// at 1e16 has already collapsed to equal coordinates.
inline constexpr double kMaxCoordinate = 1e30;

/// Throws psc::Error(InvalidMesh) for the first coordinate that is NaN, infinite or larger in
/// magnitude than kMaxCoordinate (O(M), no topology).
void checkFinite(const PositionView& positions, const std::string& what = "mesh");

/// Area-weighted vertex normals (unit length; zero for vertices in no non-degenerate triangle).
std::vector<Vec3> vertexNormals(const MeshTopology& topology, const PositionView& positions);

struct EdgeStats {
  double mean = 0.0;
  double min = 0.0;
  double max = 0.0;
};
EdgeStats edgeStats(const MeshTopology& topology, const PositionView& positions);

/// Twice the area of triangle t.
double doubleArea(const MeshTopology& topology, const PositionView& positions, std::size_t t);

/// Axis-aligned bounds and the bounding sphere about the box centre.
struct Bounds {
  Vec3 lo = Vec3::Zero();
  Vec3 hi = Vec3::Zero();
  Vec3 center() const { return 0.5 * (lo + hi); }
  double radius = 0.0;  ///< max distance of a vertex from center()
};
Bounds bounds(const PositionView& positions);

/// The rotation R (orthonormal, det +1) that maximises tr(Rᵀ A): for A = Σ (x − c)(p − ĉ)ᵀ, the
/// rotation that best carries points p (centroid ĉ) onto x (centroid c), the rotation factor of
/// A's polar decomposition. Found by the iteration of Müller et al. 2016 ("A robust method to
/// extract the rotational part of deformations") from `start` (a rotation): each round turns R by
/// the axis-angle Σ rᵢ × aᵢ / |Σ rᵢ·aᵢ| of its columns rᵢ and A's aᵢ, until a turn is below 1e-7;
/// from a nearby rotation (last step's) that takes a few rounds. Where it has not converged in 12
/// (a far start, a strongly stretched or reflected A) the answer comes from an SVD. The result goes
/// through a unit quaternion, so that rounding does not build up when it is fed back as the next
/// start. A zero or non-finite A gives `start` back.
Eigen::Matrix3d bestRotation(const Eigen::Matrix3d& a, const Eigen::Matrix3d& start = Eigen::Matrix3d::Identity());

}  // namespace psc
