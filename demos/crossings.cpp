#include "crossings.h"

#include <algorithm>
#include <cmath>
#include <limits>

namespace psc::demo {
namespace {

/// Six times the signed volume of the tetrahedron (a, b, c, d).
double orient(const Vec3& a, const Vec3& b, const Vec3& c, const Vec3& d) {
  return (b - a).cross(c - a).dot(d - a);
}

/// Which way the line from p to q passes edge XY: ((X − p) × (Y − p)) · (q − p). Swapping X and Y
/// negates it exactly (the cross product's terms only change order), so two consistently wound
/// triangles sharing an edge see a segment near it on opposite sides: exactly one of them counts it.
double edgeSide(const Vec3& p, const Vec3& q, const Vec3& x, const Vec3& y) {
  return (x - p).cross(y - p).dot(q - p);
}

bool opposite(double x, double y) { return (x < 0.0 && y > 0.0) || (x > 0.0 && y < 0.0); }

Vec3 lerp(const Vec3& x0, const Vec3& x1, double t) { return (1.0 - t) * x0 + t * x1; }

/// The positions of a moving point and triangle at time t in [0, 1], and their signed volume.
struct Motion {
  const Vec3 &p0, &p1, &a0, &b0, &c0, &a1, &b1, &c1;
  double volume(double t) const { return orient(lerp(a0, a1, t), lerp(b0, b1, t), lerp(c0, c1, t), lerp(p0, p1, t)); }
  /// The point inside the triangle at time t, up to kTunnelInsideTolerance in barycentric units.
  bool insideAt(double t) const {
    const Vec3 p = lerp(p0, p1, t), a = lerp(a0, a1, t), b = lerp(b0, b1, t), c = lerp(c0, c1, t);
    const Vec3 n = (b - a).cross(c - a);
    const double nn = n.squaredNorm();
    if (!(nn > 0.0)) return false;  // degenerate at that moment: no inside
    const double wa = n.dot((c - b).cross(p - b)) / nn, wb = n.dot((a - c).cross(p - c)) / nn,
                 wc = n.dot((b - a).cross(p - a)) / nn;
    return wa >= -kTunnelInsideTolerance && wb >= -kTunnelInsideTolerance && wc >= -kTunnelInsideTolerance;
  }
};

/// Roots in (0, 1) of k0 + k1·t + k2·t², ascending (at most two; duplicates are harmless).
int rootsInUnit(double k0, double k1, double k2, double out[2]) {
  int n = 0;
  const auto keep = [&](double t) {
    if (t > 0.0 && t < 1.0) out[n++] = t;
  };
  if (k2 == 0.0) {
    if (k1 != 0.0) keep(-k0 / k1);
    return n;
  }
  const double disc = k1 * k1 - 4.0 * k2 * k0;
  if (disc < 0.0) return n;
  // The stable pair: no cancellation between k1 and the root of the discriminant.
  const double q = -0.5 * (k1 + std::copysign(std::sqrt(disc), k1));
  keep(q / k2);
  if (q != 0.0) keep(k0 / q);
  if (n == 2 && out[0] > out[1]) std::swap(out[0], out[1]);
  return n;
}

bool finite(const Vec3& v) { return v.allFinite(); }

bool sharesVertex(const Edge& e, const Triangle& t) {
  return e[0] == t[0] || e[0] == t[1] || e[0] == t[2] || e[1] == t[0] || e[1] == t[1] || e[1] == t[2];
}

/// Grows `box` (lo, hi) by p.
void extend(Vec3& lo, Vec3& hi, const Vec3& p) {
  lo = lo.cwiseMin(p);
  hi = hi.cwiseMax(p);
}

/// Grows a box by a millionth of its size: the tests accept points a rounding error (and the
/// inside tolerance) outside the exact geometry, so the boxes that pick pairs must too, or the
/// grid would count less than brute force.
void pad(Vec3& lo, Vec3& hi) {
  const Vec3 grow = Vec3::Constant(1e-6 * (hi - lo).maxCoeff());
  lo -= grow;
  hi += grow;
}

}  // namespace

std::vector<Edge> meshEdges(const std::vector<Triangle>& triangles) {
  std::vector<Edge> edges;
  edges.reserve(3 * triangles.size());
  for (const Triangle& t : triangles)
    for (int k = 0; k < 3; ++k) {
      const Index u = t[static_cast<std::size_t>(k)], v = t[static_cast<std::size_t>((k + 1) % 3)];
      if (u != v) edges.push_back({std::min(u, v), std::max(u, v)});
    }
  std::sort(edges.begin(), edges.end());
  edges.erase(std::unique(edges.begin(), edges.end()), edges.end());
  return edges;
}

CrossingMesh crossingMesh(std::vector<Triangle> triangles) {
  CrossingMesh m;
  m.edges = meshEdges(triangles);
  m.triangles = std::move(triangles);
  return m;
}

bool segmentCrossesTriangle(const Vec3& p, const Vec3& q, const Vec3& a, const Vec3& b, const Vec3& c) {
  if (!opposite(orient(a, b, c, p), orient(a, b, c, q))) return false;
  // The line pq passes strictly inside the triangle when it sees the three edges turning the same way.
  const double s0 = edgeSide(p, q, a, b), s1 = edgeSide(p, q, b, c), s2 = edgeSide(p, q, c, a);
  return (s0 > 0.0 && s1 > 0.0 && s2 > 0.0) || (s0 < 0.0 && s1 < 0.0 && s2 < 0.0);
}

bool vertexTunnels(const Vec3& p0, const Vec3& p1, const Vec3& a0, const Vec3& b0, const Vec3& c0, const Vec3& a1,
                   const Vec3& b1, const Vec3& c1) {
  const Motion m{p0, p1, a0, b0, c0, a1, b1, c1};
  // The volume is (e1 × e2) · w with e1 = b − a, e2 = c − a, w = p − a, each linear in t: a cubic
  // k0 + k1 t + k2 t² + k3 t³. Its derivative's roots split [0, 1] into pieces where it is
  // monotone, so each piece holds at most one root, found by bisection where the ends differ in sign.
  const Vec3 e1 = b0 - a0, e2 = c0 - a0, w = p0 - a0;
  const Vec3 de1 = (b1 - a1) - e1, de2 = (c1 - a1) - e2, dw = (p1 - a1) - w;
  const Vec3 n0 = e1.cross(e2), n1 = e1.cross(de2) + de1.cross(e2), n2 = de1.cross(de2);
  const double k1 = n0.dot(dw) + n1.dot(w), k2 = n1.dot(dw) + n2.dot(w), k3 = n2.dot(dw);
  double split[2];
  const int n_split = rootsInUnit(k1, 2.0 * k2, 3.0 * k3, split);
  double lo = 0.0, f_lo = m.volume(0.0);
  for (int i = 0; i <= n_split; ++i) {
    const double hi = i < n_split ? split[i] : 1.0;
    const double f_hi = m.volume(hi);
    if (opposite(f_lo, f_hi)) {
      double l = lo, r = hi, f_l = f_lo;
      for (int it = 0; it < 100 && r - l > 0.0; ++it) {
        const double mid = 0.5 * (l + r);
        if (mid <= l || mid >= r) break;
        const double f_mid = m.volume(mid);
        if (f_mid == 0.0) {
          l = r = mid;
          break;
        }
        if (opposite(f_l, f_mid)) {
          r = mid;
        } else {
          l = mid;
          f_l = f_mid;
        }
      }
      if (m.insideAt(0.5 * (l + r))) return true;
    }
    lo = hi;
    f_lo = f_hi;
  }
  return false;
}

// --- the grid ---

bool CrossingCounter::meetsOther(const std::vector<Box>& body_boxes, std::size_t body, const Box& b) {
  for (std::size_t o = 0; o < body_boxes.size(); ++o) {
    if (o == body) continue;
    if (b.meets(body_boxes[o])) return true;
  }
  return false;
}

template <class TriBox>
void CrossingCounter::fillGrid(const std::vector<CrossingMesh>& meshes, const std::vector<Box>& body_boxes,
                               TriBox&& tri_box) {
  std::vector<Box> boxes;
  tri_body_.clear();
  tri_local_.clear();
  double extent_sum = 0.0;
  for (std::size_t b = 0; b < meshes.size(); ++b) {
    if (!meetsOther(body_boxes, b, body_boxes[b])) continue;
    for (std::size_t t = 0; t < meshes[b].triangles.size(); ++t) {
      Box box;
      if (!tri_box(b, meshes[b].triangles[t], box) || !meetsOther(body_boxes, b, box)) continue;
      boxes.push_back(box);
      tri_body_.push_back(static_cast<Index>(b));
      tri_local_.push_back(static_cast<Index>(t));
      extent_sum += (box.hi - box.lo).maxCoeff();
    }
  }
  // Cells about the size of a box.
  const double mean_extent = extent_sum / static_cast<double>(std::max<std::size_t>(boxes.size(), 1));
  grid_.build(std::move(boxes), mean_extent);
}

// --- the counts ---

std::size_t CrossingCounter::edgeCrossings(const std::vector<CrossingMesh>& meshes, const BodyPositions& x) {
  const Box empty{Vec3::Constant(std::numeric_limits<double>::infinity()),
                  Vec3::Constant(-std::numeric_limits<double>::infinity())};
  std::vector<Box> body_boxes(meshes.size(), empty);
  for (std::size_t b = 0; b < meshes.size(); ++b)
    for (const Vec3& p : x[b])
      if (finite(p)) extend(body_boxes[b].lo, body_boxes[b].hi, p);
  for (Box& box : body_boxes) pad(box.lo, box.hi);
  fillGrid(meshes, body_boxes, [&](std::size_t b, const Triangle& t, Box& box) {
    const Vec3 &p0 = x[b][t[0]], &p1 = x[b][t[1]], &p2 = x[b][t[2]];
    if (!finite(p0) || !finite(p1) || !finite(p2)) return false;
    box = {p0.cwiseMin(p1).cwiseMin(p2), p0.cwiseMax(p1).cwiseMax(p2)};
    pad(box.lo, box.hi);
    return true;
  });
  std::size_t count = 0;
  for (std::size_t a = 0; a < meshes.size(); ++a) {
    if (!meetsOther(body_boxes, a, body_boxes[a])) continue;
    for (const Edge& e : meshes[a].edges) {
      const Vec3 &p = x[a][e[0]], &q = x[a][e[1]];
      if (!finite(p) || !finite(q)) continue;
      const Box box{p.cwiseMin(q), p.cwiseMax(q)};
      if (!meetsOther(body_boxes, a, box)) continue;
      grid_.forEachInBox(box.lo, box.hi, [&](Index g) {
        const Index b = tri_body_[g], t = tri_local_[g];
        if (b == a) return;
        const Triangle& tri = meshes[b].triangles[t];
        count += segmentCrossesTriangle(p, q, x[b][tri[0]], x[b][tri[1]], x[b][tri[2]]);
      });
    }
  }
  return count;
}

std::size_t CrossingCounter::selfEdgeCrossings(const std::vector<CrossingMesh>& meshes, const BodyPositions& x) {
  std::size_t count = 0;
  std::vector<Box> boxes;
  for (std::size_t b = 0; b < meshes.size(); ++b) {
    const CrossingMesh& mesh = meshes[b];
    const std::vector<Vec3>& xb = x[b];
    boxes.clear();
    tri_local_.clear();
    double extent_sum = 0.0;
    for (std::size_t t = 0; t < mesh.triangles.size(); ++t) {
      const Vec3 &p0 = xb[mesh.triangles[t][0]], &p1 = xb[mesh.triangles[t][1]], &p2 = xb[mesh.triangles[t][2]];
      if (!finite(p0) || !finite(p1) || !finite(p2)) continue;
      Box box{p0.cwiseMin(p1).cwiseMin(p2), p0.cwiseMax(p1).cwiseMax(p2)};
      pad(box.lo, box.hi);
      extent_sum += (box.hi - box.lo).maxCoeff();
      boxes.push_back(box);
      tri_local_.push_back(static_cast<Index>(t));
    }
    if (boxes.empty()) continue;
    const double mean_extent = extent_sum / static_cast<double>(boxes.size());
    grid_.build(boxes, mean_extent);
    for (const Edge& e : mesh.edges) {
      const Vec3 &p = xb[e[0]], &q = xb[e[1]];
      if (!finite(p) || !finite(q)) continue;
      grid_.forEachInBox(p.cwiseMin(q), p.cwiseMax(q), [&](Index g) {
        const Triangle& tri = mesh.triangles[tri_local_[g]];
        if (!sharesVertex(e, tri)) count += segmentCrossesTriangle(p, q, xb[tri[0]], xb[tri[1]], xb[tri[2]]);
      });
    }
  }
  return count;
}

std::size_t CrossingCounter::tunnelledVertices(const std::vector<CrossingMesh>& meshes, const BodyPositions& before,
                                               const BodyPositions& after, const std::vector<std::vector<char>>& skip) {
  const Box empty{Vec3::Constant(std::numeric_limits<double>::infinity()),
                  Vec3::Constant(-std::numeric_limits<double>::infinity())};
  std::vector<Box> body_boxes(meshes.size(), empty);
  for (std::size_t b = 0; b < meshes.size(); ++b)
    for (std::size_t v = 0; v < after[b].size(); ++v)
      if (finite(before[b][v]) && finite(after[b][v])) {
        extend(body_boxes[b].lo, body_boxes[b].hi, before[b][v]);
        extend(body_boxes[b].lo, body_boxes[b].hi, after[b][v]);
      }
  for (Box& box : body_boxes) pad(box.lo, box.hi);
  // Swept boxes: a triangle's six positions.
  fillGrid(meshes, body_boxes, [&](std::size_t b, const Triangle& t, Box& box) {
    box = empty;
    for (Index v : t) {
      if (!finite(before[b][v]) || !finite(after[b][v])) return false;
      extend(box.lo, box.hi, before[b][v]);
      extend(box.lo, box.hi, after[b][v]);
    }
    pad(box.lo, box.hi);
    return true;
  });
  std::size_t count = 0;
  for (std::size_t a = 0; a < meshes.size(); ++a) {
    if (!meetsOther(body_boxes, a, body_boxes[a])) continue;
    for (std::size_t v = 0; v < after[a].size(); ++v) {
      if (!skip.empty() && skip[a][v]) continue;
      const Vec3 &p0 = before[a][v], &p1 = after[a][v];
      if (!finite(p0) || !finite(p1)) continue;
      const Box box{p0.cwiseMin(p1), p0.cwiseMax(p1)};
      if (!meetsOther(body_boxes, a, box)) continue;
      bool tunnelled = false;
      grid_.forEachInBox(box.lo, box.hi, [&](Index g) {
        const Index b = tri_body_[g], t = tri_local_[g];
        if (tunnelled || b == a) return;
        const Triangle& tri = meshes[b].triangles[t];
        const auto& x0 = before[b];
        const auto& x1 = after[b];
        tunnelled = vertexTunnels(p0, p1, x0[tri[0]], x0[tri[1]], x0[tri[2]], x1[tri[0]], x1[tri[1]], x1[tri[2]]);
      });
      count += tunnelled;
    }
  }
  return count;
}

std::size_t edgeCrossingsBruteForce(const std::vector<CrossingMesh>& meshes, const BodyPositions& x) {
  std::size_t count = 0;
  for (std::size_t a = 0; a < meshes.size(); ++a)
    for (const Edge& e : meshes[a].edges)
      for (std::size_t b = 0; b < meshes.size(); ++b) {
        if (b == a) continue;
        for (const Triangle& t : meshes[b].triangles)
          count += segmentCrossesTriangle(x[a][e[0]], x[a][e[1]], x[b][t[0]], x[b][t[1]], x[b][t[2]]);
      }
  return count;
}

std::size_t selfEdgeCrossingsBruteForce(const std::vector<CrossingMesh>& meshes, const BodyPositions& x) {
  std::size_t count = 0;
  for (std::size_t b = 0; b < meshes.size(); ++b)
    for (const Edge& e : meshes[b].edges)
      for (const Triangle& t : meshes[b].triangles)
        if (!sharesVertex(e, t)) count += segmentCrossesTriangle(x[b][e[0]], x[b][e[1]], x[b][t[0]], x[b][t[1]], x[b][t[2]]);
  return count;
}

std::size_t tunnelledVerticesBruteForce(const std::vector<CrossingMesh>& meshes, const BodyPositions& before,
                                        const BodyPositions& after, const std::vector<std::vector<char>>& skip) {
  std::size_t count = 0;
  for (std::size_t a = 0; a < meshes.size(); ++a)
    for (std::size_t v = 0; v < after[a].size(); ++v) {
      if (!skip.empty() && skip[a][v]) continue;
      bool tunnelled = false;
      for (std::size_t b = 0; b < meshes.size() && !tunnelled; ++b) {
        if (b == a) continue;
        const auto& x0 = before[b];
        const auto& x1 = after[b];
        for (const Triangle& t : meshes[b].triangles)
          if (vertexTunnels(before[a][v], after[a][v], x0[t[0]], x0[t[1]], x0[t[2]], x1[t[0]], x1[t[1]], x1[t[2]])) {
            tunnelled = true;
            break;
          }
      }
      count += tunnelled;
    }
  return count;
}

}  // namespace psc::demo
