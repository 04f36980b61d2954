#include "crossings.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>

#if defined(__SSE2__) && !defined(PSC_NO_SIMD)
#include <emmintrin.h>
#define PSC_CROSSINGS_SSE2 1
#endif

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

/// Edge k of triangle t, from its vertex k to vertex k + 1 (mod 3), smaller vertex first.
Edge slotEdge(const Triangle& t, int k) {
  const Index u = t[static_cast<std::size_t>(k)], w = t[static_cast<std::size_t>((k + 1) % 3)];
  return {std::min(u, w), std::max(u, w)};
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

/// Cells of the item grid are this many times the mean box size wide. Its pair loop is
/// cheap per pair (four at a time) and listing an entry is not, so cells hold several boxes: from
/// 1 to 4 the time is flat within 15% on tori and cloth, lowest about here.
constexpr double kCellPerExtent = 2.5;

constexpr float kFloatInf = std::numeric_limits<float>::infinity();

/// The rows of a float box (CrossingCounter::FloatBox) as Eigen arrays, for 4-lane arithmetic.
using FloatRow = Eigen::Array4f;
template <class Box>
Eigen::Map<const FloatRow, Eigen::Aligned16> loRow(const Box& b) {
  return Eigen::Map<const FloatRow, Eigen::Aligned16>(b.lo);
}
template <class Box>
Eigen::Map<const FloatRow, Eigen::Aligned16> hiRow(const Box& b) {
  return Eigen::Map<const FloatRow, Eigen::Aligned16>(b.hi);
}

/// An empty float box fails every test against it: items left out of the grid get one.
template <class Box>
void makeEmpty(Box& b) {
  for (int k = 0; k < 4; ++k) {
    b.lo[k] = kFloatInf;
    b.hi[k] = -kFloatInf;
  }
}
template <class Box>
bool isEmpty(const Box& b) {
  return b.lo[0] > b.hi[0];
}

/// The float box of a point: its coordinates rounded down and up.
template <class Box>
Box pointBox(const Vec3& p) {
  Box box;
  for (int k = 0; k < 3; ++k) {
    box.lo[k] = testkit::floatBelow(p[k]);
    box.hi[k] = testkit::floatAbove(p[k]);
  }
  box.lo[3] = box.hi[3] = 0.0f;
  return box;
}

/// The float box of the points boxed by a, b and c (a triangle's vertices, or an edge's with one
/// repeated), padded so that it contains the double box that pad() makes of the same points. That
/// box is the points' box grown by 1e-6 of its largest side, up to double roundings. The float box
/// before padding already contains the points' box, so its largest side is at least as large, and
/// 2e-6 of it is more than the grow; 2^-21 of each coordinate is more than the float rounding of
/// the subtraction (at most 2^-24 of it), and 1e-30 covers coordinates near zero. Beyond the float
/// range the box reaches infinity, still containing.
template <class Box>
Box paddedBox(const Box& a, const Box& b, const Box& c) {
  const FloatRow lo = loRow(a).min(loRow(b)).min(loRow(c)), hi = hiRow(a).max(hiRow(b)).max(hiRow(c));
  const FloatRow grow = FloatRow::Constant(2e-6f * (hi - lo).maxCoeff() + 1e-30f);  // lanes 3 are 0 - 0
  Box box;
  Eigen::Map<FloatRow, Eigen::Aligned16>(box.lo) = lo - (grow + lo.abs() * 0x1p-21f);
  Eigen::Map<FloatRow, Eigen::Aligned16>(box.hi) = hi + (grow + hi.abs() * 0x1p-21f);
  return box;
}

/// The smallest float box holding boxes a and b: an edge's box from its two vertices' (unpadded,
/// as edge boxes are), or a union of item boxes.
template <class Box>
Box unionBox(const Box& a, const Box& b) {
  Box box;
  Eigen::Map<FloatRow, Eigen::Aligned16>(box.lo) = loRow(a).min(loRow(b));
  Eigen::Map<FloatRow, Eigen::Aligned16>(box.hi) = hiRow(a).max(hiRow(b));
  return box;
}

/// Two float boxes (CrossingCounter::FloatBox) meet. With SSE2 a box is two registers, and the six
/// comparisons are two instructions and one branch.
template <class Box>
bool boxesMeet(const Box& a, const Box& b) {
#ifdef PSC_CROSSINGS_SSE2
  const __m128 alo = _mm_load_ps(a.lo), ahi = _mm_load_ps(a.hi), blo = _mm_load_ps(b.lo), bhi = _mm_load_ps(b.hi);
  return (_mm_movemask_ps(_mm_and_ps(_mm_cmple_ps(alo, bhi), _mm_cmple_ps(blo, ahi))) & 7) == 7;
#else
  bool meets = true;
  for (int k = 0; k < 3; ++k) meets &= (a.lo[k] <= b.hi[k]) & (b.lo[k] <= a.hi[k]);
  return meets;
#endif
}

/// Edge e of the body with vertex boxes vb and positions xe through triangle t of the body with
/// positions xt, whose box is tbox. The edge's float box against the triangle's is the filter of a
/// grid query (an edge box meeting a padded triangle box), only a little wider.
template <class Box>
inline bool crosses(const Edge& e, const Box* vb, const std::vector<Vec3>& xe, const Triangle& t,
                    const std::vector<Vec3>& xt, const Box& tbox) {
  return boxesMeet(unionBox(vb[e[0]], vb[e[1]]), tbox) &&
         segmentCrossesTriangle(xe[e[0]], xe[e[1]], xt[t[0]], xt[t[1]], xt[t[2]]);
}

/// One entry of a cell of the item grid, to be tested against the four entries of a block of the
/// same cell (CrossingCounter::CellBlock) at once: the pair is one to test when the cell is the one
/// holding the upper corner of their overlap ((ends | ends) == 7), their boxes meet and they share
/// no vertex (or are of different bodies). Most pairs of a cell fail, so this is the hot loop: with
/// SSE2 the entry's fields are broadcast to four lanes once, and a block takes about 35
/// instructions and one branch, where one pair took about 30 and a poorly predicted branch.
#ifdef PSC_CROSSINGS_SSE2
struct FarProbe {
  __m128 lo[3], hi[3];
  __m128i v[3], ends;

  template <class Block>
  FarProbe(const Block& b, int lane) {
    for (int k = 0; k < 3; ++k) {
      lo[k] = _mm_set1_ps(b.lo[k][lane]);
      hi[k] = _mm_set1_ps(b.hi[k][lane]);
      v[k] = _mm_set1_epi32(static_cast<int>(b.v[k][lane]));
    }
    ends = _mm_set1_epi32(static_cast<int>(b.ends[lane]));
  }

  /// Bit l set: entry l of `o` and this one are a far pair.
  template <class Block>
  int farMask(const Block& o) const {
    const __m128i o_ends = _mm_load_si128(reinterpret_cast<const __m128i*>(o.ends));
    __m128 pair = _mm_castsi128_ps(_mm_cmpeq_epi32(_mm_or_si128(ends, o_ends), _mm_set1_epi32(7)));
    __m128i shared = _mm_setzero_si128();
    for (int k = 0; k < 3; ++k) {
      const __m128 below = _mm_cmple_ps(lo[k], _mm_load_ps(o.hi[k])), above = _mm_cmple_ps(_mm_load_ps(o.lo[k]), hi[k]);
      pair = _mm_and_ps(pair, _mm_and_ps(below, above));
      const __m128i ov = _mm_load_si128(reinterpret_cast<const __m128i*>(o.v[k]));
      shared = _mm_or_si128(shared, _mm_or_si128(_mm_or_si128(_mm_cmpeq_epi32(ov, v[0]), _mm_cmpeq_epi32(ov, v[1])),
                                                 _mm_cmpeq_epi32(ov, v[2])));
    }
    return _mm_movemask_ps(_mm_andnot_ps(_mm_castsi128_ps(shared), pair));
  }
};
#else
struct FarProbe {
  float lo[3], hi[3];
  Index v[3];
  std::uint32_t ends;

  template <class Block>
  FarProbe(const Block& b, int lane) : ends(b.ends[lane]) {
    for (int k = 0; k < 3; ++k) {
      lo[k] = b.lo[k][lane];
      hi[k] = b.hi[k][lane];
      v[k] = b.v[k][lane];
    }
  }

  template <class Block>
  int farMask(const Block& o) const {
    int mask = 0;
    for (int l = 0; l < 4; ++l) {
      bool pair = (ends | o.ends[l]) == 7u;
      for (int k = 0; k < 3; ++k) pair &= (lo[k] <= o.hi[k][l]) & (o.lo[k][l] <= hi[k]);
      for (int k = 0; k < 3; ++k) pair &= (o.v[k][l] != v[0]) & (o.v[k][l] != v[1]) & (o.v[k][l] != v[2]);
      mask |= int(pair) << l;
    }
    return mask;
  }
};
#endif

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
  if (topology_.size() < meshes.size()) topology_.resize(meshes.size());
  // Bodies near another first, on their vertices' boxes, padded (a body's triangles' padded boxes
  // stay inside its own): only they have items.
  const Box empty{Vec3::Constant(std::numeric_limits<double>::infinity()),
                  Vec3::Constant(-std::numeric_limits<double>::infinity())};
  std::vector<Box> body_boxes(meshes.size(), empty);
  for (std::size_t b = 0; b < meshes.size(); ++b)
    for (const Vec3& p : x[b])
      if (finite(p)) extend(body_boxes[b].lo, body_boxes[b].hi, p);
  for (Box& box : body_boxes) pad(box.lo, box.hi);
  left_out_.clear();
  lone_.clear();
  vertex_boxes_.clear();
  boxes_.clear();
  bodies_.clear();
  for (std::size_t b = 0; b < meshes.size(); ++b)
    if (meetsOther(body_boxes, b, body_boxes[b])) bodies_.push_back(addItems(topology(b, meshes[b]), x[b], nullptr));
  if (bodies_.size() < 2) return 0;
  // Then the items near another body, on the union of each body's item boxes (which holds the
  // float box of every triangle and edge of it); the others leave the grid.
  std::vector<FloatBox> unions(bodies_.size(), FloatBox{{kFloatInf, kFloatInf, kFloatInf, 0.0f},
                                                         {-kFloatInf, -kFloatInf, -kFloatInf, 0.0f}});
  for (std::size_t k = 0; k < bodies_.size(); ++k)
    for (std::size_t i = bodies_[k].first_item; i < bodies_[k].first_item + bodies_[k].items(); ++i)
      if (!isEmpty(boxes_[i])) unions[k] = unionBox(unions[k], boxes_[i]);
  ItemSpan span;
  item_body_.resize(boxes_.size());
  for (std::size_t k = 0; k < bodies_.size(); ++k)
    for (std::size_t i = bodies_[k].first_item; i < bodies_[k].first_item + bodies_[k].items(); ++i) {
      item_body_[i] = static_cast<Index>(k);
      if (isEmpty(boxes_[i])) continue;
      bool near = false;
      for (std::size_t o = 0; o < bodies_.size(); ++o) near |= o != k && boxesMeet(boxes_[i], unions[o]);
      if (near)
        span.add(boxes_[i]);
      else
        makeEmpty(boxes_[i]);
    }
  if (span.in_grid < 2) return 0;
  // One grid, the body for vertices: items of one body make no pair.
  std::size_t count = 0;
  const auto edgesThrough = [&](std::size_t from, std::size_t to) {
    const BodyItems &f = bodies_[item_body_[from]], &t = bodies_[item_body_[to]];
    const std::size_t tri = to - t.first_item;
    if (tri >= t.topo->triangles.size()) return;  // a lone edge
    const Triangle& triangle = t.topo->triangles[tri];
    const FloatBox* vb = vertex_boxes_.data() + f.first_vertex;
    forEachOwnedEdge(f, from - f.first_item,
                     [&](const Edge& e) { count += crosses(e, vb, *f.x, triangle, *t.x, boxes_[to]); });
  };
  forEachFarPair(
      span,
      [&](std::size_t i) {
        const Index k = item_body_[i];
        return Triangle{k, k, k};
      },
      [&](std::size_t i, std::size_t j) {
        edgesThrough(i, j);
        edgesThrough(j, i);
      });
  return count;
}

std::size_t CrossingCounter::selfEdgeCrossings(const std::vector<CrossingMesh>& meshes, const BodyPositions& x) {
  std::size_t count = 0;
  for (std::size_t b = 0; b < meshes.size(); ++b) count += selfEdgeCrossings(meshes, x, b);
  return count;
}

std::size_t CrossingCounter::selfEdgeCrossings(const std::vector<CrossingMesh>& meshes, const BodyPositions& x,
                                               std::size_t b) {
  if (topology_.size() < meshes.size()) topology_.resize(meshes.size());
  left_out_.clear();
  lone_.clear();
  vertex_boxes_.clear();
  boxes_.clear();
  ItemSpan span;
  const BodyItems body = addItems(topology(b, meshes[b]), x[b], &span);
  return selfCrossingsOf(body, span);
}

CrossingCounter::ItemSpan::ItemSpan() : lo(FloatRow::Constant(kFloatInf)), hi(-lo) {}

void CrossingCounter::ItemSpan::add(const FloatBox& box) {
  lo = lo.min(loRow(box));
  hi = hi.max(hiRow(box));
  extent_sum += static_cast<double>((hiRow(box) - loRow(box)).head<3>().maxCoeff());
  ++in_grid;
}

const CrossingCounter::Topology& CrossingCounter::topology(std::size_t b, const CrossingMesh& mesh) {
  Topology& topo = topology_[b];
  // Comparing the arrays costs a memcmp per step, far less than the count; a mesh is not known by
  // its address, as a new one may well reuse the old one's memory.
  const auto same = [](const auto& u, const auto& v) {
    return u.size() == v.size() && (u.empty() || std::memcmp(u.data(), v.data(), u.size() * sizeof(u[0])) == 0);
  };
  const std::vector<Triangle>& tris = mesh.triangles;
  if (topo.owned.size() == tris.size() && same(topo.triangles, tris) && same(topo.edges, mesh.edges)) return topo;
  topo.triangles = tris;
  topo.edges = mesh.edges;
  topo.owned.assign(tris.size(), 0);
  topo.edge_owner.assign(mesh.edges.size(), kInvalidIndex);
  topo.lone.clear();
  Index vertices = 0;
  for (const Triangle& t : tris)
    for (Index v : t) vertices = std::max(vertices, v + 1);
  for (const Edge& e : mesh.edges) vertices = std::max({vertices, e[0] + 1, e[1] + 1});
  // Owners: the edges listed by first vertex (a counting sort, so repeats keep their order), and
  // for each edge of each triangle the first entry equal to it that no triangle owns yet. Entries
  // repeated once too often, in no triangle or not written smaller first stay lone.
  std::vector<Index> first(static_cast<std::size_t>(vertices) + 1, 0), by_first(mesh.edges.size());
  for (const Edge& e : mesh.edges) ++first[e[0] + 1];
  for (Index v = 0; v < vertices; ++v) first[v + 1] += first[v];
  {
    std::vector<Index> cursor(first.begin(), first.end() - 1);
    for (std::size_t e = 0; e < mesh.edges.size(); ++e) by_first[cursor[mesh.edges[e][0]]++] = static_cast<Index>(e);
  }
  for (std::size_t t = 0; t < tris.size(); ++t)
    for (int k = 0; k < 3; ++k) {
      const Edge key = slotEdge(tris[t], k);
      if (key[0] == key[1]) continue;
      for (Index at = first[key[0]]; at < first[key[0] + 1]; ++at) {
        const Index e = by_first[at];
        if (mesh.edges[e][1] == key[1] && topo.edge_owner[e] == kInvalidIndex) {
          topo.edge_owner[e] = static_cast<Index>(t);
          topo.owned[t] |= static_cast<std::uint8_t>(1u << k);
          break;
        }
      }
    }
  for (std::size_t e = 0; e < mesh.edges.size(); ++e)
    if (topo.edge_owner[e] == kInvalidIndex) topo.lone.push_back(mesh.edges[e]);
  // The near pairs: the triangles around the owner's vertices (each once), less those touching
  // the edge.
  std::vector<std::pair<Index, Index>> vertex_triangle;
  vertex_triangle.reserve(3 * tris.size());
  for (std::size_t t = 0; t < tris.size(); ++t)
    for (Index v : tris[t]) vertex_triangle.emplace_back(v, static_cast<Index>(t));
  const IndexRows around = IndexRows::fromPairs(vertices, vertex_triangle);
  topo.near = IndexRows{};
  std::vector<Index> ring;
  for (std::size_t t = 0; t < tris.size(); ++t) {
    if (topo.owned[t] == 0) continue;
    ring.clear();
    for (Index v : tris[t])
      for (Index o : around.row(v))
        if (o != t) ring.push_back(o);
    std::sort(ring.begin(), ring.end());
    ring.erase(std::unique(ring.begin(), ring.end()), ring.end());
    for (int k = 0; k < 3; ++k) {
      if (!(topo.owned[t] >> k & 1)) continue;
      const Edge e = slotEdge(tris[t], k);
      for (Index o : ring)
        if (!sharesVertex(e, tris[o])) topo.near.items.push_back(o);
      topo.near.offsets.push_back(static_cast<Index>(topo.near.items.size()));
    }
  }
  return topo;
}

CrossingCounter::BodyItems CrossingCounter::addItems(const Topology& topo, const std::vector<Vec3>& x, ItemSpan* span) {
  const std::vector<Triangle>& tris = topo.triangles;
  BodyItems body{&topo, &x, boxes_.size(), vertex_boxes_.size(), left_out_.size(), lone_.size(), 0};
  bool all_finite = true;
  for (const Vec3& p : x) all_finite &= finite(p);
  left_out_.resize(body.first_triangle + tris.size(), 0);
  std::uint8_t* left_out = left_out_.data() + body.first_triangle;
  if (all_finite) {
    lone_.insert(lone_.end(), topo.lone.begin(), topo.lone.end());
  } else {
    for (std::size_t t = 0; t < tris.size(); ++t)
      left_out[t] = !finite(x[tris[t][0]]) || !finite(x[tris[t][1]]) || !finite(x[tris[t][2]]);
    for (const Edge& e : topo.lone)
      if (finite(x[e[0]]) && finite(x[e[1]])) lone_.push_back(e);
    for (std::size_t e = 0; e < topo.edges.size(); ++e) {
      const Index owner = topo.edge_owner[e];
      const Edge& edge = topo.edges[e];
      if (owner != kInvalidIndex && left_out[owner] && finite(x[edge[0]]) && finite(x[edge[1]])) lone_.push_back(edge);
    }
  }
  body.lone_count = lone_.size() - body.first_lone;
  // Boxes in float only: the grid's cells are found from these too, so that two boxes meeting in
  // float meet in the cells. Each vertex is rounded outwards once, and the items' boxes are made
  // from those (paddedBox), containing the padded double boxes of testkit's grids (pad()).
  vertex_boxes_.resize(body.first_vertex + x.size());
  FloatBox* vb = vertex_boxes_.data() + body.first_vertex;
  for (std::size_t v = 0; v < x.size(); ++v) vb[v] = pointBox<FloatBox>(x[v]);
  boxes_.resize(body.first_item + body.items());
  FloatBox* box = boxes_.data() + body.first_item;
  for (std::size_t t = 0; t < tris.size(); ++t) {
    if (left_out[t]) {
      makeEmpty(box[t]);
      continue;
    }
    box[t] = paddedBox(vb[tris[t][0]], vb[tris[t][1]], vb[tris[t][2]]);
    if (span != nullptr) span->add(box[t]);
  }
  for (std::size_t l = 0; l < body.lone_count; ++l) {
    const Edge& e = lone_[body.first_lone + l];
    FloatBox& b = box[tris.size() + l];
    b = paddedBox(vb[e[0]], vb[e[1]], vb[e[1]]);
    if (span != nullptr) span->add(b);
  }
  return body;
}

template <class Vertices, class Pair>
void CrossingCounter::forEachFarPair(const ItemSpan& span, Vertices&& vertices, Pair&& pair) {
  // Cells a few boxes wide (kCellPerExtent), at most 2n + 64 of them (as testkit::BoxGrid).
  // Which cell a coordinate falls in only has to grow with it, and the same for every item: a
  // multiplication and a truncation (coordinates minus the origin are not negative) instead of
  // floor(/), on a box's rows of floats.
  const Vec3 origin = span.lo.head<3>().cast<double>().matrix();
  const Vec3 extent = (span.hi.head<3>().cast<double>().matrix() - origin).cwiseMax(Vec3::Constant(1e-12));
  const double mean_extent = span.extent_sum / static_cast<double>(span.in_grid);
  double cell = std::max(kCellPerExtent * mean_extent, 1e-9 * extent.maxCoeff());
  std::int32_t dims[3] = {1, 1, 1};
  const bool spread = extent.allFinite() && cell > 0.0;  // else one cell holds all
  if (spread) {
    const double cap = 2.0 * static_cast<double>(span.in_grid) + 64.0;
    for (;;) {
      double cells = 1.0;
      for (int k = 0; k < 3; ++k) cells *= std::floor(extent[k] / cell) + 1.0;
      if (cells <= cap) break;
      cell *= 1.26;
    }
    for (int k = 0; k < 3; ++k) dims[k] = static_cast<std::int32_t>(std::floor(extent[k] / cell)) + 1;
  }
  const FloatRow origin_row(span.lo[0], span.lo[1], span.lo[2], 0.0f);
  const FloatRow inv_cell = FloatRow::Constant(spread ? static_cast<float>(1.0 / cell) : 0.0f);
  const FloatRow top(static_cast<float>(dims[0] - 1), static_cast<float>(dims[1] - 1),
                     static_cast<float>(dims[2] - 1), 0.0f);
  // The cells [r0..r3] × [r1..r4] × [r2..r5] that a box covers.
  const auto cellRange = [&](const FloatBox& box, std::int32_t r[6]) {
    if (!spread) {
      std::fill(r, r + 6, 0);
      return;
    }
    const Eigen::Array4i rlo = ((loRow(box) - origin_row) * inv_cell).min(top).cast<std::int32_t>();
    const Eigen::Array4i rhi = ((hiRow(box) - origin_row) * inv_cell).min(top).cast<std::int32_t>();
    for (int k = 0; k < 3; ++k) {
      r[k] = rlo[k];
      r[3 + k] = rhi[k];
    }
  };
  const std::size_t cells = static_cast<std::size_t>(dims[0]) * static_cast<std::size_t>(dims[1]) *
                            static_cast<std::size_t>(dims[2]);
  const auto cellIndex = [&](std::int32_t cx, std::int32_t cy, std::int32_t cz) {
    return (static_cast<std::size_t>(cz) * static_cast<std::size_t>(dims[1]) + static_cast<std::size_t>(cy)) *
               static_cast<std::size_t>(dims[0]) +
           static_cast<std::size_t>(cx);
  };

  // Two passes over the items' cells: count per cell, then list. A cell gets its entries rounded
  // up to whole blocks, or none when it has a single one: that makes no pair.
  const std::size_t n = boxes_.size();
  cell_fill_.assign(cells, 0u);
  std::int32_t r[6];
  for (std::size_t i = 0; i < n; ++i) {
    if (isEmpty(boxes_[i])) continue;
    cellRange(boxes_[i], r);
    for (std::int32_t cz = r[2]; cz <= r[5]; ++cz)
      for (std::int32_t cy = r[1]; cy <= r[4]; ++cy)
        for (std::int32_t cx = r[0]; cx <= r[3]; ++cx) ++cell_fill_[cellIndex(cx, cy, cz)];
  }
  cell_offsets_.resize(cells + 1);
  cell_offsets_[0] = 0;
  for (std::size_t c = 0; c < cells; ++c) {
    const std::uint32_t entries = cell_fill_[c];
    cell_offsets_[c + 1] = cell_offsets_[c] + (entries >= 2 ? (entries + 3) / 4 * 4 : 0u);
    cell_fill_[c] = cell_offsets_[c];  // now the fill cursor
  }
  cell_blocks_.resize(cell_offsets_[cells] / 4);
  for (std::size_t i = 0; i < n; ++i) {
    const FloatBox& box = boxes_[i];
    if (isEmpty(box)) continue;
    const Triangle v = vertices(i);
    cellRange(box, r);
    for (std::int32_t cz = r[2]; cz <= r[5]; ++cz)
      for (std::int32_t cy = r[1]; cy <= r[4]; ++cy)
        for (std::int32_t cx = r[0]; cx <= r[3]; ++cx) {
          const std::size_t c = cellIndex(cx, cy, cz);
          if (cell_offsets_[c + 1] == cell_offsets_[c]) continue;
          const std::uint32_t at = cell_fill_[c]++;
          CellBlock& block = cell_blocks_[at / 4];
          const std::uint32_t l = at % 4;
          for (int k = 0; k < 3; ++k) {
            block.lo[k][l] = box.lo[k];
            block.hi[k][l] = box.hi[k];
            block.v[k][l] = v[static_cast<std::size_t>(k)];
          }
          block.ends[l] = std::uint32_t(cx == r[3]) | std::uint32_t(cy == r[4]) << 1 | std::uint32_t(cz == r[5]) << 2;
          block.item[l] = static_cast<Index>(i);
        }
  }
  for (std::size_t c = 0; c < cells; ++c)
    for (std::uint32_t at = cell_fill_[c]; at < cell_offsets_[c + 1]; ++at) {
      CellBlock& block = cell_blocks_[at / 4];
      const std::uint32_t l = at % 4;
      for (int k = 0; k < 3; ++k) {
        block.lo[k][l] = kFloatInf;
        block.hi[k][l] = -kFloatInf;
        block.v[k][l] = 0;
      }
      block.ends[l] = 0;
      block.item[l] = 0;
    }

  // Every pair of entries of every cell, each entry against the following ones, four at a time.
  for (std::size_t c = 0; c < cells; ++c) {
    const std::uint32_t entries = cell_fill_[c] - cell_offsets_[c];
    const CellBlock* blocks = cell_blocks_.data() + cell_offsets_[c] / 4;
    const std::uint32_t block_count = (entries + 3) / 4;
    for (std::uint32_t a = 0; a + 1 < entries; ++a) {
      const CellBlock& a_block = blocks[a / 4];
      const int a_lane = static_cast<int>(a % 4);
      const FarProbe probe(a_block, a_lane);
      for (std::uint32_t b = a / 4; b < block_count; ++b) {
        int mask = probe.farMask(blocks[b]);
        if (b == a / 4) mask &= 0xF << (a_lane + 1);  // its own block: the lanes after it only
        if (mask == 0) continue;
        for (int l = 0; l < 4; ++l)
          if (mask >> l & 1) pair(a_block.item[a_lane], blocks[b].item[l]);
      }
    }
  }
}

template <class F>
inline void CrossingCounter::forEachOwnedEdge(const BodyItems& body, std::size_t i, F&& f) const {
  const std::vector<Triangle>& tris = body.topo->triangles;
  if (i >= tris.size()) {
    f(lone_[body.first_lone + (i - tris.size())]);
    return;
  }
  const unsigned owned = body.topo->owned[i];
  for (int k = 0; k < 3; ++k)
    if (owned >> k & 1u) f(slotEdge(tris[i], k));
}

std::size_t CrossingCounter::selfCrossingsOf(const BodyItems& body, const ItemSpan& span) {
  if (span.in_grid < 2) return 0;  // a triangle's own edges all share its vertices
  const Topology& topo = *body.topo;
  const std::vector<Triangle>& tris = topo.triangles;
  const std::vector<Vec3>& x = *body.x;
  const FloatBox* vb = vertex_boxes_.data() + body.first_vertex;
  const std::uint8_t* left_out = left_out_.data() + body.first_triangle;
  std::size_t count = 0;
  // The near pairs, from the topology. A triangle left out owns no edge here, but its rows are
  // still skipped over; one left out as a near triangle has an empty box.
  std::size_t row = 0;
  for (std::size_t t = 0; t < tris.size(); ++t) {
    const unsigned owned = topo.owned[t];
    if (owned == 0) continue;
    if (left_out[t]) {
      row += (owned & 1u) + (owned >> 1 & 1u) + (owned >> 2 & 1u);
      continue;
    }
    for (int k = 0; k < 3; ++k) {
      if (!(owned >> k & 1u)) continue;
      const Edge e = slotEdge(tris[t], k);
      for (Index o : topo.near.row(row++)) count += crosses(e, vb, x, tris[o], x, boxes_[body.first_item + o]);
    }
  }
  // The far pairs, from the grid: two items sharing no vertex.
  const auto edgesThrough = [&](std::size_t from, std::size_t to) {
    const std::size_t t = to - body.first_item;
    if (t >= tris.size()) return;  // a lone edge
    forEachOwnedEdge(body, from - body.first_item,
                     [&](const Edge& e) { count += crosses(e, vb, x, tris[t], x, boxes_[to]); });
  };
  forEachFarPair(
      span,
      [&](std::size_t i) {
        const std::size_t local = i - body.first_item;
        if (local < tris.size()) return tris[local];
        const Edge& e = lone_[body.first_lone + (local - tris.size())];
        return Triangle{e[0], e[1], e[1]};
      },
      [&](std::size_t i, std::size_t j) {
        edgesThrough(i, j);
        edgesThrough(j, i);
      });
  return count;
}

std::size_t CrossingCounter::tunnelledVertices(const std::vector<CrossingMesh>& meshes, const BodyPositions& before,
                                               const BodyPositions& after, const std::vector<std::vector<char>>& skip,
                                               std::size_t* passed) {
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
  std::size_t count = 0, all = 0;
  for (std::size_t a = 0; a < meshes.size(); ++a) {
    if (!meetsOther(body_boxes, a, body_boxes[a])) continue;
    for (std::size_t v = 0; v < after[a].size(); ++v) {
      const bool skipped = !skip.empty() && skip[a][v];
      if (skipped && passed == nullptr) continue;
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
      count += tunnelled && !skipped;
      all += tunnelled;
    }
  }
  if (passed != nullptr) *passed = all;
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
