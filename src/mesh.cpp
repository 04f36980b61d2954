#include "psc/mesh.h"

#include "psc/error.h"

#include <Eigen/SVD>

#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>
#include <sstream>
#include <unordered_map>

namespace psc {

namespace {

Index findRoot(std::vector<Index>& parent, Index x) {
  while (parent[x] != x) {
    parent[x] = parent[parent[x]];
    x = parent[x];
  }
  return x;
}

}  // namespace

IndexRows IndexRows::fromPairs(std::size_t rows, const std::vector<std::pair<Index, Index>>& pairs) {
  // Counting sort by row (stable), then each row sorted and deduplicated on its own: O(pairs +
  // Σ row log row) instead of a global sort. Rows usually arrive sorted already (callers loop in
  // index order), and then the per-row pass only checks it.
  IndexRows out;
  out.offsets.assign(rows + 1, 0);
  for (const auto& p : pairs) ++out.offsets[p.first + 1];
  for (std::size_t r = 0; r < rows; ++r) out.offsets[r + 1] += out.offsets[r];
  out.items.resize(pairs.size());
  {
    std::vector<Index> cursor(out.offsets.begin(), out.offsets.end() - 1);
    for (const auto& p : pairs) out.items[cursor[p.first]++] = p.second;
  }
  Index write = 0;
  for (std::size_t r = 0; r < rows; ++r) {
    const auto first = out.items.begin() + out.offsets[r], last = out.items.begin() + out.offsets[r + 1];
    if (!std::is_sorted(first, last)) std::sort(first, last);
    const auto end = std::unique(first, last);
    out.offsets[r] = write;
    write = static_cast<Index>(std::copy(first, end, out.items.begin() + write) - out.items.begin());
  }
  out.offsets[rows] = write;
  out.items.resize(write);
  out.items.shrink_to_fit();
  return out;
}

std::string MeshReport::summary() const {
  std::ostringstream s;
  s << components << " component(s), " << degenerate_triangles << " degenerate and " << sliver_triangles
    << " sliver triangle(s), " << duplicate_vertices << " duplicate and " << isolated_vertices
    << " isolated vertex(es), " << non_manifold_edges << " non-manifold, " << boundary_edges << " boundary and "
    << inconsistent_winding_edges << " inconsistently wound edge(s)";
  return s.str();
}

MeshTopology::MeshTopology(std::vector<Triangle> triangles, std::size_t vertex_count)
    : triangles_(std::move(triangles)), vertex_count_(vertex_count) {
  if (vertex_count_ == 0) throw Error(ErrorCode::InvalidMesh, "the mesh has no vertices");
  if (triangles_.empty()) throw Error(ErrorCode::InvalidMesh, "the mesh has no triangles");
  if (vertex_count_ >= kInvalidIndex) throw Error(ErrorCode::InvalidMesh, "too many vertices for 32-bit indices");
  for (std::size_t t = 0; t < triangles_.size(); ++t)
    for (int k = 0; k < 3; ++k)
      if (triangles_[t][static_cast<std::size_t>(k)] >= vertex_count_) {
        std::ostringstream s;
        s << "triangle " << t << " has vertex index " << triangles_[t][static_cast<std::size_t>(k)]
          << " out of range (the mesh has " << vertex_count_ << " vertices)";
        throw Error(ErrorCode::InvalidMesh, s.str());
      }

  std::vector<std::pair<Index, Index>> adj;
  std::vector<std::pair<Index, Index>> vt;
  adj.reserve(triangles_.size() * 6);
  vt.reserve(triangles_.size() * 3);
  for (std::size_t t = 0; t < triangles_.size(); ++t) {
    const Triangle& tri = triangles_[t];
    for (std::size_t k = 0; k < 3; ++k) {
      const Index a = tri[k], b = tri[(k + 1) % 3];
      vt.emplace_back(a, static_cast<Index>(t));
      if (a == b) continue;
      adj.emplace_back(a, b);
      adj.emplace_back(b, a);
    }
  }
  adjacency_ = IndexRows::fromPairs(vertex_count_, adj);
  vertex_triangles_ = IndexRows::fromPairs(vertex_count_, vt);
  std::vector<Index> parent(vertex_count_);
  std::iota(parent.begin(), parent.end(), Index{0});
  for (Index v = 0; v < vertex_count_; ++v)
    for (Index n : neighbors(v)) {
      const Index ra = findRoot(parent, v), rb = findRoot(parent, n);
      if (ra != rb) parent[std::max(ra, rb)] = std::min(ra, rb);
    }
  // Components numbered in order of their lowest vertex: deterministic.
  component_.assign(vertex_count_, kInvalidIndex);
  std::vector<Index> label(vertex_count_, kInvalidIndex);
  for (Index v = 0; v < vertex_count_; ++v) {
    const Index r = findRoot(parent, v);
    if (label[r] == kInvalidIndex) label[r] = static_cast<Index>(component_count_++);
    component_[v] = label[r];
  }
}

std::vector<std::array<Index, 2>> MeshTopology::edges() const {
  std::vector<std::array<Index, 2>> out;
  out.reserve(edgeCount());
  for (Index v = 0; v < vertex_count_; ++v)
    for (Index n : neighbors(v))
      if (v < n) out.push_back({v, n});
  return out;
}

std::size_t MeshTopology::bytes() const {
  return triangles_.capacity() * sizeof(Triangle) + adjacency_.bytes() + vertex_triangles_.bytes() +
         component_.capacity() * sizeof(Index);
}

void checkFinite(const PositionView& positions, const std::string& what) {
  for (std::size_t i = 0; i < positions.size(); ++i) {
    const Vec3 p = positions[i];
    if (!p.allFinite()) {
      std::ostringstream s;
      s << what << ": vertex " << i << " has a non-finite coordinate (" << p.x() << ", " << p.y() << ", " << p.z()
        << ")";
      throw Error(ErrorCode::InvalidMesh, s.str());
    }
    if (p.cwiseAbs().maxCoeff() > kMaxCoordinate) {
      std::ostringstream s;
      s << what << ": vertex " << i << " has a coordinate beyond +-" << kMaxCoordinate << " (" << p.x() << ", "
        << p.y() << ", " << p.z() << ")";
      throw Error(ErrorCode::InvalidMesh, s.str());
    }
  }
}

MeshReport validate(const MeshTopology& topology, const PositionView& positions, const std::string& what) {
  if (positions.empty()) throw Error(ErrorCode::InvalidMesh, what + ": no positions were given");
  if (positions.size() != topology.vertexCount()) {
    std::ostringstream s;
    s << what << ": the position view has " << positions.size() << " vertices but the triangles use "
      << topology.vertexCount();
    throw Error(ErrorCode::InvalidMesh, s.str());
  }
  checkFinite(positions, what);

  MeshReport r;
  r.components = 0;
  for (std::size_t t = 0; t < topology.triangleCount(); ++t) {
    const Triangle& tri = topology.triangle(t);
    const bool repeated = tri[0] == tri[1] || tri[1] == tri[2] || tri[0] == tri[2];
    const Vec3 a = positions[tri[0]], b = positions[tri[1]], c = positions[tri[2]];
    const double area2 = (b - a).cross(c - a).norm();
    const double longest = std::max({(b - a).norm(), (c - b).norm(), (a - c).norm()});
    if (repeated || area2 == 0.0 || longest == 0.0) {
      if (r.degenerate_triangles++ == 0) r.first_degenerate_triangle = static_cast<Index>(t);
    } else if (area2 / longest < 1e-3 * longest) {  // smallest altitude = 2·area / longest edge
      ++r.sliver_triangles;
    }
  }

  // Duplicate positions: sort vertex indices by coordinates.
  std::vector<Index> order(topology.vertexCount());
  std::iota(order.begin(), order.end(), Index{0});
  std::vector<Vec3> pts(topology.vertexCount());
  for (std::size_t i = 0; i < pts.size(); ++i) pts[i] = positions[i];
  std::sort(order.begin(), order.end(), [&](Index i, Index j) {
    const Vec3 &p = pts[i], &q = pts[j];
    if (p.x() != q.x()) return p.x() < q.x();
    if (p.y() != q.y()) return p.y() < q.y();
    if (p.z() != q.z()) return p.z() < q.z();
    return i < j;
  });
  for (std::size_t k = 1; k < order.size(); ++k)
    if (pts[order[k]] == pts[order[k - 1]]) ++r.duplicate_vertices;

  for (Index v = 0; v < topology.vertexCount(); ++v)
    if (topology.vertexTriangles(v).empty()) ++r.isolated_vertices;

  // Edge use counts and winding: an interior edge of a consistently wound surface is traversed
  // once as (a,b) and once as (b,a).
  std::unordered_map<std::uint64_t, std::pair<int, int>> uses;  // key(min,max) → (forward, backward)
  uses.reserve(topology.triangleCount() * 3);
  for (const Triangle& tri : topology.triangles())
    for (std::size_t k = 0; k < 3; ++k) {
      const Index a = tri[k], b = tri[(k + 1) % 3];
      if (a == b) continue;
      const std::uint64_t key = (std::uint64_t{std::min(a, b)} << 32) | std::max(a, b);
      auto& u = uses[key];
      (a < b ? u.first : u.second)++;
    }
  for (const auto& kv : uses) {
    const int total = kv.second.first + kv.second.second;
    if (total == 1) ++r.boundary_edges;
    if (total > 2) ++r.non_manifold_edges;
    if (total == 2 && kv.second.first != 1) ++r.inconsistent_winding_edges;
  }
  // Components over triangles only: isolated vertices are counted separately above.
  std::vector<char> seen(topology.componentCount(), 0);
  for (Index v = 0; v < topology.vertexCount(); ++v)
    if (!topology.vertexTriangles(v).empty() && !seen[topology.componentOf()[v]]) {
      seen[topology.componentOf()[v]] = 1;
      ++r.components;
    }
  return r;
}

std::vector<Vec3> vertexNormals(const MeshTopology& topology, const PositionView& positions) {
  std::vector<Vec3> n(topology.vertexCount(), Vec3::Zero());
  for (const Triangle& tri : topology.triangles()) {
    const Vec3 a = positions[tri[0]], b = positions[tri[1]], c = positions[tri[2]];
    const Vec3 area_normal = (b - a).cross(c - a);  // |.| = 2·area: area weighting for free
    for (Index v : tri) n[v] += area_normal;
  }
  for (Vec3& v : n) {
    const double len = v.norm();
    v = len > 0.0 ? Vec3(v / len) : Vec3::Zero();
  }
  return n;
}

EdgeStats edgeStats(const MeshTopology& topology, const PositionView& positions) {
  EdgeStats s;
  if (topology.edgeCount() == 0) return s;
  double sum = 0.0;
  s.min = std::numeric_limits<double>::infinity();
  for (Index v = 0; v < topology.vertexCount(); ++v) {
    const Vec3 p = positions[v];
    for (Index n : topology.neighbors(v)) {
      if (n < v) continue;
      const double len = (positions[n] - p).norm();
      sum += len;
      s.min = std::min(s.min, len);
      s.max = std::max(s.max, len);
    }
  }
  s.mean = sum / static_cast<double>(topology.edgeCount());
  return s;
}

double doubleArea(const MeshTopology& topology, const PositionView& positions, std::size_t t) {
  const Triangle& tri = topology.triangle(t);
  const Vec3 a = positions[tri[0]];
  return (positions[tri[1]] - a).cross(positions[tri[2]] - a).norm();
}

Bounds bounds(const PositionView& positions) {
  Bounds b;
  if (positions.size() == 0) return b;
  b.lo = b.hi = positions[0];
  for (std::size_t i = 1; i < positions.size(); ++i) {
    const Vec3 p = positions[i];
    b.lo = b.lo.cwiseMin(p);
    b.hi = b.hi.cwiseMax(p);
  }
  const Vec3 c = b.center();
  double r2 = 0.0;
  for (std::size_t i = 0; i < positions.size(); ++i) r2 = std::max(r2, (positions[i] - c).squaredNorm());
  b.radius = std::sqrt(r2);
  return b;
}

Eigen::Matrix3d bestRotation(const Eigen::Matrix3d& a, const Eigen::Matrix3d& start) {
  const double scale = a.norm();
  if (!(scale > 0.0) || !std::isfinite(scale)) return start;
  Eigen::Matrix3d rot = start;
  bool converged = false;
  for (int round = 0; round < 12 && !converged; ++round) {
    const Vec3 torque = rot.col(0).cross(a.col(0)) + rot.col(1).cross(a.col(1)) + rot.col(2).cross(a.col(2));
    const double align = std::abs(rot.col(0).dot(a.col(0)) + rot.col(1).dot(a.col(1)) + rot.col(2).dot(a.col(2)));
    const Vec3 omega = torque / (align + 1e-9 * scale);
    const double angle = omega.norm();
    converged = !(angle > 1e-7);
    if (!converged) rot = Eigen::AngleAxisd(angle, omega / angle).toRotationMatrix() * rot;
  }
  if (!converged) {
    // Far from the start, or a strongly stretched or reflected A, where the iteration crawls.
    const Eigen::JacobiSVD<Eigen::Matrix3d> svd(a, Eigen::ComputeFullU | Eigen::ComputeFullV);
    Eigen::Matrix3d d = Eigen::Matrix3d::Identity();
    if ((svd.matrixU() * svd.matrixV().transpose()).determinant() < 0.0) d(2, 2) = -1.0;
    rot = svd.matrixU() * d * svd.matrixV().transpose();
  }
  Eigen::Quaterniond q(rot);
  q.normalize();
  return q.toRotationMatrix();
}

}  // namespace psc
