#include "bounds.h"

#include "psc/error.h"

#include <algorithm>
#include <cmath>

namespace psc::detail {

namespace {

MotionBox emptyBox() {
  MotionBox b;
  b.lo = Vec3::Constant(std::numeric_limits<double>::infinity());
  b.hi = -b.lo;
  return b;
}

void grow(MotionBox& into, const MotionBox& b) {
  into.lo = into.lo.cwiseMin(b.lo);
  into.hi = into.hi.cwiseMax(b.hi);
  into.motion = std::max(into.motion, b.motion);
}

// Boxes grown by ga and gb overlap.
bool overlap(const MotionBox& a, double ga, const MotionBox& b, double gb) {
  const double g = ga + gb;
  return (a.lo.array() <= b.hi.array() + g).all() && (b.lo.array() <= a.hi.array() + g).all();
}

bool inside(const Vec3& x, const Vec3& lo, const Vec3& hi, double r) {
  return (x.array() >= lo.array() - r).all() && (x.array() <= hi.array() + r).all();
}

}  // namespace

namespace {

// The refit is the one pass that reads every vertex each step: read the view's raw scalars
// directly instead of going through PositionView::operator[]'s per-call type switch.
template <typename T>
MotionBox chunkBox(const char* base, std::size_t stride, const char* prev, std::size_t prev_stride,
                   IndexRange box_vertices, IndexRange own_vertices, double& sum) {
  MotionBox box;
  double lo[3] = {std::numeric_limits<double>::infinity(), std::numeric_limits<double>::infinity(),
                  std::numeric_limits<double>::infinity()};
  double hi[3] = {-lo[0], -lo[1], -lo[2]};
  for (Index v : box_vertices) {
    const T* p = reinterpret_cast<const T*>(base + v * stride);
    for (int a = 0; a < 3; ++a) {
      const double x = static_cast<double>(p[a]);
      sum += x;
      lo[a] = x < lo[a] ? x : lo[a];
      hi[a] = x > hi[a] ? x : hi[a];
    }
  }
  if (prev != nullptr)
    for (Index v : own_vertices) {
      const T* p = reinterpret_cast<const T*>(base + v * stride);
      const T* q = reinterpret_cast<const T*>(prev + v * prev_stride);
      const double dx = double(p[0]) - double(q[0]), dy = double(p[1]) - double(q[1]), dz = double(p[2]) - double(q[2]);
      const double m2 = dx * dx + dy * dy + dz * dz;
      sum += m2;
      box.motion = m2 > box.motion ? m2 : box.motion;
    }
  box.motion = std::sqrt(box.motion);
  box.lo = Vec3(lo[0], lo[1], lo[2]);
  box.hi = Vec3(hi[0], hi[1], hi[2]);
  return box;
}

}  // namespace

void refitBounds(Body& b) {
  const ChunkLists& ch = b.chunks;
  b.chunk_box.resize(ch.count());
  b.region_box.assign(b.regionCount(), emptyBox());
  b.body_box = emptyBox();
  bool finite = true;
  const char* base = static_cast<const char*>(b.positions.data());
  const std::size_t stride = b.positions.strideBytes();
  // The previous view is read with the current one's scalar type; mixed types take the slow path.
  const bool same_type = b.previous.empty() || b.previous.scalar() == b.positions.scalar();
  const char* prev = b.previous.empty() || !same_type ? nullptr : static_cast<const char*>(b.previous.data());
  const std::size_t prev_stride = b.previous.strideBytes();
  const bool is_float = b.positions.scalar() == PositionView::Scalar::Float32;
  for (std::size_t c = 0; c < ch.count(); ++c) {
    double sum = 0.0;  // min/max may drop a NaN silently; a plain sum keeps it
    MotionBox box = is_float ? chunkBox<float>(base, stride, prev, prev_stride, ch.box_vertices.row(c),
                                               ch.vertices.row(c), sum)
                             : chunkBox<double>(base, stride, prev, prev_stride, ch.box_vertices.row(c),
                                                ch.vertices.row(c), sum);
    if (!same_type)
      for (Index v : ch.vertices.row(c)) box.motion = std::max(box.motion, b.vertexMotion(v));
    // Finite but beyond kMaxCoordinate (a blown-up simulation) is rejected like NaN.
    finite = finite && std::isfinite(sum) && box.lo.cwiseAbs().maxCoeff() <= kMaxCoordinate &&
             box.hi.cwiseAbs().maxCoeff() <= kMaxCoordinate;
    b.chunk_box[c] = box;
  }
  if (!finite) {
    checkFinite(b.positions, b.label());
    if (!b.previous.empty()) checkFinite(b.previous, b.label() + " (previous positions)");
  }
  for (Index r = 0; r < b.regionCount(); ++r) {
    for (Index c = ch.region_begin[r]; c < ch.region_begin[r + 1]; ++c) grow(b.region_box[r], b.chunk_box[c]);
    grow(b.body_box, b.region_box[r]);
  }
}

namespace {

struct PairContext {
  const Body& vb;
  const Body& tb;
  double margin_sum;
  double motion_factor;
  std::vector<std::uint64_t>& out;
  BoundsCounters& counters;
};

// Vertices of chunk cv (of ctx.vb) against triangles of chunk ct (of ctx.tb).
void chunkCandidates(const PairContext& ctx, Index cv, Index ct, std::vector<Vec3>& tri_lo, std::vector<Vec3>& tri_hi) {
  const MotionBox& tbox = ctx.tb.chunk_box[ct];
  const IndexRange tris = ctx.tb.chunks.triangles.row(ct);
  bool boxes_ready = false;
  for (Index v : ctx.vb.chunks.vertices.row(cv)) {
    const Vec3 x = ctx.vb.positions[v];
    const double r = ctx.margin_sum + ctx.motion_factor * ctx.vb.vertexMotion(v);
    ++ctx.counters.vertices;
    if (!inside(x, tbox.lo, tbox.hi, r)) continue;
    if (!boxes_ready) {
      tri_lo.resize(tris.size());
      tri_hi.resize(tris.size());
      const MeshTopology& topo = *ctx.tb.topology;
      for (std::size_t k = 0; k < tris.size(); ++k) {
        const Triangle& tri = topo.triangle(tris[k]);
        const Vec3 a = ctx.tb.positions[tri[0]], b = ctx.tb.positions[tri[1]], c = ctx.tb.positions[tri[2]];
        tri_lo[k] = a.cwiseMin(b).cwiseMin(c);
        tri_hi[k] = a.cwiseMax(b).cwiseMax(c);
      }
      ctx.counters.triangles += tris.size();
      boxes_ready = true;
    }
    for (std::size_t k = 0; k < tris.size(); ++k) {
      ++ctx.counters.probes;
      if (inside(x, tri_lo[k], tri_hi[k], r)) ctx.out.push_back((std::uint64_t{v} << 32) | tris[k]);
    }
  }
}

}  // namespace

void collectByBounds(const std::vector<Body*>& bodies, double motion_factor, double flag_pad,
                     std::vector<FlaggedPair>& flagged, std::vector<CandidatePair>& candidates,
                     BoundsCounters& counters) {
  struct Group {
    BodyId vb, tb;
    std::vector<std::uint64_t> keys;
  };
  std::vector<Group> groups;
  std::vector<Vec3> tri_lo, tri_hi;
  std::vector<Index> near_a, near_b, near_rb;
  for (std::size_t i = 0; i < bodies.size(); ++i) {
    const Body& A = *bodies[i];
    const double ga = A.margin + motion_factor * A.body_box.motion + flag_pad;
    for (std::size_t j = i + 1; j < bodies.size(); ++j) {
      const Body& B = *bodies[j];
      const double gb = B.margin + motion_factor * B.body_box.motion + flag_pad;
      if (!overlap(A.body_box, ga, B.body_box, gb)) continue;
      Group ab{A.id, B.id, {}}, ba{B.id, A.id, {}};
      const PairContext to_b{A, B, A.margin + B.margin, motion_factor, ab.keys, counters};
      const PairContext to_a{B, A, A.margin + B.margin, motion_factor, ba.keys, counters};
      // Only regions that reach the other body's box can pair up: filter both sides first.
      near_rb.clear();
      for (Index rj = 0; rj < B.regionCount(); ++rj)
        if (overlap(B.region_box[rj], B.margin + motion_factor * B.region_box[rj].motion + flag_pad, A.body_box, ga))
          near_rb.push_back(rj);
      if (near_rb.empty()) continue;
      for (Index ri = 0; ri < A.regionCount(); ++ri) {
        const MotionBox& boxI = A.region_box[ri];
        const double gI = A.margin + motion_factor * boxI.motion;
        if (!overlap(boxI, gI + flag_pad, B.body_box, gb)) continue;
        for (Index rj : near_rb) {
          const MotionBox& boxJ = B.region_box[rj];
          const double gJ = B.margin + motion_factor * boxJ.motion;
          if (!overlap(boxI, gI + flag_pad, boxJ, gJ + flag_pad)) continue;
          FlaggedPair f;
          f.body_a = A.id;  // bodies are ordered by id
          f.region_a = ri;
          f.body_b = B.id;
          f.region_b = rj;
          f.by_bounds = true;
          flagged.push_back(f);
          if (!overlap(boxI, gI, boxJ, gJ)) continue;  // flagged at μ, but no contact radius reach
          // Only the chunks of I that reach J's box and of J that reach I's box can pair up.
          near_a.clear();
          near_b.clear();
          for (Index c = A.chunks.region_begin[ri]; c < A.chunks.region_begin[ri + 1]; ++c)
            if (overlap(A.chunk_box[c], A.margin + motion_factor * A.chunk_box[c].motion, boxJ, gJ)) near_a.push_back(c);
          if (near_a.empty()) continue;
          for (Index c = B.chunks.region_begin[rj]; c < B.chunks.region_begin[rj + 1]; ++c)
            if (overlap(B.chunk_box[c], B.margin + motion_factor * B.chunk_box[c].motion, boxI, gI)) near_b.push_back(c);
          for (Index ca : near_a) {
            const MotionBox& bxa = A.chunk_box[ca];
            const double gca = A.margin + motion_factor * bxa.motion;
            for (Index cb : near_b) {
              const MotionBox& bxb = B.chunk_box[cb];
              if (!overlap(bxa, gca, bxb, B.margin + motion_factor * bxb.motion)) continue;
              ++counters.chunk_pairs;
              chunkCandidates(to_b, ca, cb, tri_lo, tri_hi);
              chunkCandidates(to_a, cb, ca, tri_lo, tri_hi);
            }
          }
        }
      }
      if (!ab.keys.empty()) groups.push_back(std::move(ab));
      if (!ba.keys.empty()) groups.push_back(std::move(ba));
    }
  }
  std::sort(groups.begin(), groups.end(),
            [](const Group& x, const Group& y) { return x.vb != y.vb ? x.vb < y.vb : x.tb < y.tb; });
  std::size_t total = candidates.size();
  for (const Group& g : groups) total += g.keys.size();
  candidates.reserve(total);
  for (const Group& g : groups)
    for (std::uint64_t k : g.keys)
      candidates.push_back({g.vb, static_cast<Index>(k >> 32), g.tb, static_cast<Index>(k & 0xFFFFFFFFu)});
}

}  // namespace psc::detail
