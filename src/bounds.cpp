#include "bounds.h"

#include "psc/error.h"

#include <algorithm>
#include <array>
#include <atomic>
#include <cassert>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <optional>
#include <type_traits>
#include <unordered_map>

#if defined(__SSE2__)
#include <emmintrin.h>
#endif
#if defined(__x86_64__) && defined(__GNUC__)
#include <immintrin.h>
#define PSC_HAVE_AVX2_PATH 1
#endif

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

/// A box grown by the contact reach of what it holds: its body's margin plus the motion term of
/// its fastest vertex. Two boxes whose grown versions do not overlap hold no pair within
/// margin_A + margin_B + motion_factor·|Δx| of each other, in either direction.
struct Grown {
  Vec3 lo, hi;
  double g;
};

/// factor × motion, 0 for a factor of 0 whatever the motion: the packed refit squares motions in
/// single precision, and a displacement above about 1.8e19 in one step (finite positions go up
/// to kMaxCoordinate) leaves a chunk's motion infinite, where 0 × inf would make every growth and
/// test after it NaN and drop the body's pairs (a review's finding: motion_factor 0, float positions).
/// With a positive factor an infinite growth holds everything: slower, never wrong.
double motionTerm(double factor, double motion) { return factor == 0.0 ? 0.0 : factor * motion; }

Grown grown(const MotionBox& b, double margin, double motion_factor) {
  const double g = margin + motionTerm(motion_factor, b.motion);
  return {b.lo.array() - g, b.hi.array() + g, g};
}

bool overlap(const Grown& a, const Grown& b) {
  return (a.lo.array() <= b.hi.array()).all() && (b.lo.array() <= a.hi.array()).all();
}

/// Axis along which the box is longest: the sweep axis that separates the most.
int longestAxis(const Vec3& lo, const Vec3& hi) {
  Eigen::Index axis = 0;
  (hi - lo).maxCoeff(&axis);
  return static_cast<int>(axis);
}

template <typename T>
Vec3 load(const char* base, std::size_t stride, Index v) {
  const T* p = reinterpret_cast<const T*>(base + static_cast<std::size_t>(v) * stride);
  return {static_cast<double>(p[0]), static_cast<double>(p[1]), static_cast<double>(p[2])};
}

// The refit is the one pass that reads every vertex each step. It streams through the vertices in
// index order, i.e. through the positions' memory in order, reading the view's raw scalars (no
// per-call type switch), and grows the box of the vertex's own chunk and of each chunk whose
// triangles it is in. `sum` keeps a NaN that min/max would drop silently.
// With `swept`, a vertex's previous position goes into the same boxes instead of a motion term;
// with `paths`, besides it.
/// The refit's pass without the rest-shape bound.
struct NoRestFit {
  void own(std::size_t /*v*/, Index /*c*/, const Vec3& /*x*/, const Vec3* /*displacement*/) {}
  void foreign(std::size_t /*v*/, Index /*c*/, const Vec3& /*x*/) {}
};

/// The rest-shape bound's part of the refit's pass (RestFit in body.h): y = x − R_r·rest into the
/// y-box of each chunk the vertex is in, and Σ x, Σ x restᵀ for the vertex's own region, summed
/// here while the region stays the same (vertices of one region mostly come in runs).
class RestFitPass {
 public:
  RestFitPass(RestFit& f, const ChunkLists& ch, const RestShape& rest) : f_(f), ch_(ch), rest_(rest) {}
  [[gnu::always_inline]] void own(std::size_t v, Index c, const Vec3& x, const Vec3* displacement) {
    const Index r = ch_.region_of[c];
    if (r != region_) switchTo(r);
    if (displacement != nullptr) {
      f_.move_lo[c] = f_.move_lo[c].cwiseMin(*displacement);
      f_.move_hi[c] = f_.move_hi[c].cwiseMax(*displacement);
      sum_motion_ += *displacement;
      moved_ += 1.0;
    }
    const Vec3 p = rest_[v];
    y_ = x - rot_ * p;
    f_.chunk_lo[c] = f_.chunk_lo[c].cwiseMin(y_);
    f_.chunk_hi[c] = f_.chunk_hi[c].cwiseMax(y_);
    sum_x_ += x;
    xr_.noalias() += x * p.transpose();
  }
  [[gnu::always_inline]] void foreign(std::size_t v, Index c, const Vec3& x) {
    const Index r = ch_.region_of[c];
    const Vec3 y = r == region_ ? y_ : Vec3(x - f_.rot[r] * rest_[v]);
    f_.chunk_lo[c] = f_.chunk_lo[c].cwiseMin(y);
    f_.chunk_hi[c] = f_.chunk_hi[c].cwiseMax(y);
  }
  /// Adds the current run's sums to its region; call once after the pass.
  void flush() {
    f_.sum_motion += sum_motion_;
    f_.moved += moved_;
    sum_motion_.setZero();
    moved_ = 0.0;
    if (region_ == kInvalidIndex) return;
    f_.region_sum_x[region_] += sum_x_;
    f_.region_xr[region_] += xr_;
    sum_x_.setZero();
    xr_.setZero();
  }

 private:
  [[gnu::noinline]] void switchTo(Index r) {
    flush();
    region_ = r;
    rot_ = f_.rot[r];
  }

  RestFit& f_;
  const ChunkLists& ch_;
  const RestShape& rest_;
  Eigen::Matrix3d rot_ = Eigen::Matrix3d::Identity();
  Eigen::Matrix3d xr_ = Eigen::Matrix3d::Zero();
  Vec3 sum_x_ = Vec3::Zero();
  Vec3 sum_motion_ = Vec3::Zero();
  double moved_ = 0.0;
  Vec3 y_ = Vec3::Zero();
  Index region_ = kInvalidIndex;
};

/// The refit's one pass over the vertices in memory order. With `copy`, each vertex's three
/// coordinates are also written there, packed (3 T per vertex), for the repartition check's
/// measures.
template <typename T, typename Hook>
void streamBoxes(const ChunkLists& ch, const char* base, std::size_t stride, const char* prev, std::size_t prev_stride,
                 bool swept, bool paths, std::vector<MotionBox>& boxes, double& sum, Hook& hook, T* copy) {
  const std::size_t n = ch.vertexCount();
  for (std::size_t v = 0; v < n; ++v) {
    // Positions usually live inside larger records (Bullet's nodes are 256 bytes): fetch ahead.
    __builtin_prefetch(base + (v + 24) * stride);
    if (prev != nullptr) __builtin_prefetch(prev + (v + 24) * prev_stride);
    const Index c = ch.chunkOf(v);
    if (c == kInvalidIndex) continue;
    const T* p = reinterpret_cast<const T*>(base + v * stride);
    if (copy != nullptr) std::copy(p, p + 3, copy + 3 * v);
    const double x = static_cast<double>(p[0]), y = static_cast<double>(p[1]), z = static_cast<double>(p[2]);
    double s = x + y + z;  // one addition per vertex into `sum`, the loop's only chain
    MotionBox& box = boxes[c];
    box.lo = box.lo.cwiseMin(Vec3(x, y, z));
    box.hi = box.hi.cwiseMax(Vec3(x, y, z));
    Vec3 q_lo(x, y, z), q_hi(x, y, z);
    if (prev != nullptr) {
      const T* q = reinterpret_cast<const T*>(prev + v * prev_stride);
      const Vec3 qv{static_cast<double>(q[0]), static_cast<double>(q[1]), static_cast<double>(q[2])};
      if (swept || paths) {
        q_lo = q_lo.cwiseMin(qv);
        q_hi = q_hi.cwiseMax(qv);
        box.lo = box.lo.cwiseMin(qv);
        box.hi = box.hi.cwiseMax(qv);
      }
      if (swept) {
        s += qv.sum();
        hook.own(v, c, Vec3(x, y, z), nullptr);
      } else {
        const Vec3 d = Vec3(x, y, z) - qv;
        const double m2 = d.squaredNorm();
        s += m2;
        box.motion = m2 > box.motion ? m2 : box.motion;  // squared until the end of the pass
        hook.own(v, c, Vec3(x, y, z), &d);
      }
    } else {
      hook.own(v, c, Vec3(x, y, z), nullptr);
    }
    sum += s;
    ch.foreign.forEach(static_cast<Index>(v), [&](Index f) {
      MotionBox& fb = boxes[f];
      fb.lo = fb.lo.cwiseMin(q_lo);
      fb.hi = fb.hi.cwiseMax(q_hi);
      hook.foreign(v, f, Vec3(x, y, z));
    });
  }
}

#if defined(__SSE2__)
// The packed single-precision pass's pieces, shared by streamBoxesFloat and (with AVX2)
// streamBoxesFloatRestFit. Per chunk, its own vertices' box, lo = (x, y, z, 0) and hi = (x, y, z,
// squared motion), and the box of the corners it borrows (lane 3 zero), merged at the end
// (finishPackedBoxes); one more borrowed box past the last takes what empty foreign slots name and
// is thrown away.
// __m128's alignment attribute is not part of the vector's type: std::array and std::vector align by
// alignof, which malloc's 16 bytes meet.
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wignored-attributes"
using PackedBox = std::array<__m128, 2>;
#pragma GCC diagnostic pop

inline PackedBox emptyPackedBox() {
  const float inf = std::numeric_limits<float>::infinity();
  return {_mm_set1_ps(inf), _mm_setr_ps(-inf, -inf, -inf, 0.0f)};
}

/// (x, y, z, 0) from three floats, without reading past z (the view's records may end right after
/// it); x and y by one 8-byte load, since positions are only 4-byte aligned.
[[gnu::always_inline]] inline __m128 loadPoint(const float* at) {
  double xy;
  std::memcpy(&xy, at, sizeof xy);
  return _mm_movelh_ps(_mm_castpd_ps(_mm_set_sd(xy)), _mm_load_ss(at + 2));
}

[[gnu::always_inline]] inline void growPacked(PackedBox& box, __m128 lo, __m128 hi) {
  box[0] = _mm_min_ps(box[0], lo);
  box[1] = _mm_max_ps(box[1], hi);
}

/// (x, y, z, |x − q|²) from x = (x, y, z, 0) and q likewise, the squared motion in single precision.
[[gnu::always_inline]] inline __m128 withMotion(__m128 xv, __m128 qv) {
  const __m128 d = _mm_sub_ps(xv, qv);
  const __m128 d2 = _mm_mul_ps(d, d);
  const __m128 m2 = _mm_add_ss(_mm_add_ss(d2, _mm_shuffle_ps(d2, d2, 1)), _mm_movehl_ps(d2, d2));
  return _mm_movelh_ps(xv, _mm_unpacklo_ps(_mm_movehl_ps(xv, xv), m2));
}

/// Whether the previous positions need prefetches of their own: another stride, or records a cache
/// line or more away from the current ones (otherwise one prefetch brings both, or the line after
/// it, which the hardware fetches with it: see streamBoxesFloat).
inline bool prefetchApart(const char* base, std::size_t stride, const char* prev, std::size_t prev_stride) {
  if (prev == nullptr) return false;
  const auto at = reinterpret_cast<std::uintptr_t>(base), before = reinterpret_cast<std::uintptr_t>(prev);
  return prev_stride != stride || (before > at ? before - at : at - before) >= 64;
}

/// streamBoxesFloat's loop over the vertices, in a function of its own so that what it touches
/// lives in registers: its arrays as local pointers, and whether there are previous positions and
/// a packed copy as compile-time choices. Inlined into refitBounds, the loop kept its pointers,
/// bounds and strides on the stack and reloaded them, and the thread-local boxes' data pointer,
/// after each box store (the stores are through a type that may alias anything), with the point
/// registers spilled around them: on 8 tori × 50,000 vertices (`psc_midphase_bench
/// --benchmark_filter=8x50000`, three interleaved invocations) the refit went from 10.3–10.8 to
/// 8.8–9.3 ns per vertex with this and the branch on the second slot, and in the demo (`psc_demo
/// --scene tori_pile --bodies 8 --resolution 50000 --steps 40 --pipeline sensors --truth none
/// --no-penetration`, two alternating runs) `refit_ms_mean` from 4.10–4.19 to 3.47–3.57 ms.
///
/// `Slot`: the type of ChunkLists::foreign's slots (its slotWidth() bytes). Each vertex updates the
/// box of its first slot without a branch (half the vertices have one, too irregularly for a
/// branch); an empty slot names the box past the last chunk, which is thrown away. The second slot
/// (one vertex in ten: 7.7% on the 50,000-vertex tori) is updated behind a branch, which also ends
/// the chain of updates through the thrown-away box every vertex without one made.
template <typename Slot, bool kPrev, bool kCopy>
[[gnu::noinline]] __m128 streamBoxesFloatLoop(const std::uint8_t* __restrict owner, const std::uint8_t* __restrict slots,
                                              std::size_t n, const char* base, std::size_t stride, const char* prev,
                                              std::size_t prev_stride, bool prev_apart, PackedBox* __restrict box,
                                              PackedBox* __restrict borrowed, float* __restrict copy, Slot none) {
  __m128 nan = _mm_setzero_ps();
  for (std::size_t v = 0; v < n; ++v) {
    __builtin_prefetch(base + (v + 24) * stride);
    if (kPrev && prev_apart) __builtin_prefetch(prev + (v + 24) * prev_stride);
    Slot c;
    std::memcpy(&c, owner + sizeof(Slot) * v, sizeof c);
    if (c == none) continue;  // in no chunk (a vertex of no region)
    const float* p = reinterpret_cast<const float*>(base + v * stride);
    if (kCopy) std::memcpy(copy + 3 * v, p, 3 * sizeof(float));
    const __m128 xv = loadPoint(p);  // (x, y, z, 0)
    nan = _mm_or_ps(nan, _mm_cmpunord_ps(xv, xv));
    __m128 xm = xv;
    if (kPrev) {
      const __m128 qv = loadPoint(reinterpret_cast<const float*>(prev + v * prev_stride));
      nan = _mm_or_ps(nan, _mm_cmpunord_ps(qv, qv));
      xm = withMotion(xv, qv);  // (x, y, z, m2)
    }
    growPacked(box[c], xv, xm);
    Slot f[2];
    std::memcpy(f, slots + 2 * sizeof(Slot) * v, sizeof f);
    growPacked(borrowed[f[0]], xv, xv);  // lane 3: 0, the motion stays the own vertices'
    if (f[1] != none) growPacked(borrowed[f[1]], xv, xv);
  }
  return nan;
}

/// The end of streamBoxesFloat: each chunk's box as the refit leaves it (its own vertices' packed
/// box `own` and the corners its triangles borrow, `borrowed`, in double, the motion the square
/// root of the packed squared motion raised by 1e-6 relative, so never below the double value)
/// into `boxes`, and the own box alone into `own_boxes`. Returns whether every coordinate is
/// within ±kMaxCoordinate and every motion finite (`nan`: the pass met a NaN).
bool finishPackedBoxes(const PackedBox* own, const PackedBox* borrowed, std::size_t chunks, bool nan,
                       std::vector<MotionBox>& boxes, std::vector<OwnBox>& own_boxes) {
  boxes.resize(chunks);
  own_boxes.resize(chunks);
  const __m128 sign = _mm_set1_ps(-0.0f);
  const __m128 xyz = _mm_castsi128_ps(_mm_setr_epi32(-1, -1, -1, 0));
  __m128 biggest = _mm_setzero_ps();
  bool motions_finite = true;
  for (std::size_t c = 0; c < chunks; ++c) {
    alignas(16) float l[4], h[4];
    _mm_store_ps(l, own[c][0]);
    _mm_store_ps(h, own[c][1]);
    own_boxes[c] = OwnBox{{l[0], l[1], l[2]}, {h[0], h[1], h[2]}};
    // The own box's fourth lanes: 0 and the squared motion; the borrowed box's: +infinity and 0.
    const __m128 lo = _mm_min_ps(borrowed[c][0], own[c][0]), hi = _mm_max_ps(borrowed[c][1], own[c][1]);
    biggest = _mm_max_ps(biggest, _mm_andnot_ps(sign, _mm_and_ps(lo, xyz)));
    biggest = _mm_max_ps(biggest, _mm_andnot_ps(sign, _mm_and_ps(hi, xyz)));
    _mm_store_ps(l, lo);
    _mm_store_ps(h, hi);
    MotionBox& b = boxes[c];
    b.lo = Vec3(l[0], l[1], l[2]);
    b.hi = Vec3(h[0], h[1], h[2]);
    const double m2 = static_cast<double>(h[3]) * (1.0 + 1e-6);
    motions_finite = motions_finite && m2 <= std::numeric_limits<double>::max();
    b.motion = std::sqrt(m2);
  }
  alignas(16) float g[4];
  _mm_store_ps(g, biggest);
  const double largest = std::max({static_cast<double>(g[0]), static_cast<double>(g[1]), static_cast<double>(g[2])});
  return !nan && motions_finite && largest <= kMaxCoordinate;
}

/// streamBoxes for the common step: single-precision positions, the radius bound and no rest fit
/// (Bullet's nodes); with `copy`, the packed copy of the positions as streamBoxes makes it.
/// Everything stays in single precision, four lanes (x, y, z, 0): the boxes are the same values as
/// streamBoxes's (min and max only pick coordinates); the squared motion is rounded in single
/// precision and raised by 1e-6 relative, so never below the double value; a NaN is caught by an
/// unordered compare, an infinity by the boxes' or the motion's check.
/// On 8 tori × 50,000 vertices the refit went from 3.42 to 3.16 ms a step with the boxes alone
/// packed, to about 3.06 ms with the motion too, and to 2.90–2.94 with the motion carried in the
/// upper box's fourth lane and one prefetch for Bullet's node (m_x and m_q are 16 bytes apart; in
/// a node array that starts 32 bytes into a line, as Bullet's allocator places one that glibc maps
/// on its own, they lie in two lines, and the hardware's prefetchers bring the second: a prefetch
/// of it measured no difference, docs/DECISIONS.md "Stop 33"; reading one line instead, with
/// psc::bullet::alignLargeBulletBlocks, took the refit from 5.5–6.0 to 4.9–5.4 ns a vertex,
/// docs/BULLET.md "Node arrays on cache lines")
/// (psc_demo --scene tori_pile --bodies 8 --resolution 50000 --steps 40 --pipeline sensors
/// --truth none, refit_ms_mean, two or three alternating runs each).
/// The corners a chunk borrows grow a box of their own, merged with the own vertices' at the end
/// (the same boxes; the own one is kept too: Body::chunk_own), and that end also takes the motions'
/// square roots and checks the range, in one pass over the chunks. Returns whether every box and
/// motion is finite and within ±kMaxCoordinate.
template <typename Slot>
bool streamBoxesFloat(const ChunkLists& ch, const char* base, std::size_t stride, const char* prev,
                      std::size_t prev_stride, std::vector<MotionBox>& boxes, std::vector<OwnBox>& own_boxes,
                      float* copy) {
  const std::size_t n = ch.vertexCount(), chunks = ch.count();
  const std::uint8_t* slots = ch.foreign.slotData();
  assert(ch.owner.width() == sizeof(Slot) && ch.foreign.slotWidth() == sizeof(Slot));
  thread_local std::vector<PackedBox> own, borrowed;
  own.assign(chunks, emptyPackedBox());
  borrowed.assign(chunks + 1, emptyPackedBox());
  const bool prev_apart = prefetchApart(base, stride, prev, prev_stride);
  const std::uint8_t* owner = ch.owner.data();
  PackedBox* o = own.data();
  PackedBox* b = borrowed.data();
  const auto none = static_cast<Slot>(ch.foreign.none());
  // The loop for this call's two compile-time choices (without previous positions prev is null and
  // prev_apart false; without a copy, copy is null).
  const auto loop = [&](auto with_prev, auto with_copy) {
    return streamBoxesFloatLoop<Slot, decltype(with_prev)::value, decltype(with_copy)::value>(
        owner, slots, n, base, stride, prev, prev_stride, prev_apart, o, b, copy, none);
  };
  using Yes = std::true_type;
  using No = std::false_type;
  const __m128 nan = prev != nullptr ? (copy != nullptr ? loop(Yes{}, Yes{}) : loop(Yes{}, No{}))
                                     : (copy != nullptr ? loop(No{}, Yes{}) : loop(No{}, No{}));
  // The rare third and later foreign chunks of a vertex.
  for (const auto& [v, f] : ch.foreign.extra()) {
    const __m128 xv = loadPoint(reinterpret_cast<const float*>(base + std::size_t{v} * stride));
    growPacked(b[f], xv, xv);
  }
  return finishPackedBoxes(o, b, chunks, _mm_movemask_ps(nan) != 0, boxes, own_boxes);
}
#endif

// Area and longest edge of the triangles a chunk owns, from the refit's packed copy of the positions.
// Every operation is written out, in the order measureChunkAvx2 repeats lane by lane: the cross
// product as Eigen's, squared norms as (x² + y²) + z², each area added in the triangles' order.
inline void measureTriangle(const Vec3& a, const Vec3& b, const Vec3& c, double& area, double& max_edge2) {
  const Vec3 ab = b - a, ac = c - a, bc = c - b;
  const double nx = ab.y() * ac.z() - ab.z() * ac.y(), ny = ab.z() * ac.x() - ab.x() * ac.z(),
               nz = ab.x() * ac.y() - ab.y() * ac.x();
  area += 0.5 * std::sqrt((nx * nx + ny * ny) + nz * nz);
  const auto norm2 = [](const Vec3& e) { return (e.x() * e.x() + e.y() * e.y()) + e.z() * e.z(); };
  max_edge2 = std::max({max_edge2, norm2(ab), norm2(ac), norm2(bc)});
}

template <typename T>
void measureChunk(const ChunkLists& ch, Index chunk, const char* base, std::size_t stride, double& area,
                  double& max_edge2) {
  for (std::size_t k = ch.triangle_begin[chunk]; k < ch.triangle_begin[chunk + 1]; ++k) {
    const Triangle tri = ch.triangle(chunk, k);
    measureTriangle(load<T>(base, stride, tri[0]), load<T>(base, stride, tri[1]), load<T>(base, stride, tri[2]), area,
                    max_edge2);
  }
}

std::atomic<bool> g_avx2_allowed{true};  ///< allowAvx2Probes

#if defined(PSC_HAVE_AVX2_PATH)
bool useAvx2Probes() { return g_avx2_allowed.load(std::memory_order_relaxed) && avx2ProbesAvailable(); }

/// (x² + y²) + z², lane by lane.
[[gnu::target("avx2")]] inline __m256d squaredNorms(__m256d x, __m256d y, __m256d z) {
  return _mm256_add_pd(_mm256_add_pd(_mm256_mul_pd(x, x), _mm256_mul_pd(y, y)), _mm256_mul_pd(z, z));
}

/// row[at[0..3]], by four loads: on processors with the Gather Data Sampling mitigation a
/// vpgather is several times slower than that.
[[gnu::target("avx2")]] inline __m256d gather(const double* row, const Index at[4]) {
  return _mm256_setr_pd(row[at[0]], row[at[1]], row[at[2]], row[at[3]]);
}

/// measureChunk on single-precision positions (`stride` bytes apart), four triangles at a time
/// (AVX2, chosen at run time). The chunk's vertex table is first read into `table` (x, y, z rows in double), so
/// each corner is one load from there; each lane does measureChunk's operations in its order, and
/// the areas are added one by one in the triangles' order: the same bits.
[[gnu::target("avx2")]] void measureChunkAvx2(const ChunkLists& ch, Index chunk, const char* base, std::size_t stride,
                                              std::vector<double>& table, double& area, double& max_edge2) {
  using V = __m256d;
  const Index* t = ch.table.data() + ch.table_begin[chunk];
  const std::size_t n = ch.table_begin[chunk + 1] - ch.table_begin[chunk];
  table.resize(3 * n);
  double* tx = table.data();
  double* ty = tx + n;
  double* tz = ty + n;
  for (std::size_t i = 0; i < n; ++i) {
    const float* p = reinterpret_cast<const float*>(base + std::size_t{t[i]} * stride);
    tx[i] = p[0];
    ty[i] = p[1];
    tz[i] = p[2];
  }
  const std::size_t begin = ch.triangle_begin[chunk], end = ch.triangle_begin[chunk + 1];
  std::size_t k = begin;
  V edge2 = _mm256_set1_pd(max_edge2);
  for (; k + 4 <= end; k += 4) {
    // Corner j of the four triangles, as positions in the table.
    Index ia[4], ib[4], ic[4];
    for (std::size_t l = 0; l < 4; ++l) {
      ia[l] = ch.corners[3 * (k + l)];
      ib[l] = ch.corners[3 * (k + l) + 1];
      ic[l] = ch.corners[3 * (k + l) + 2];
    }
    const V ax = gather(tx, ia), ay = gather(ty, ia), az = gather(tz, ia);
    const V bx = gather(tx, ib), by = gather(ty, ib), bz = gather(tz, ib);
    const V cx = gather(tx, ic), cy = gather(ty, ic), cz = gather(tz, ic);
    const V abx = _mm256_sub_pd(bx, ax), aby = _mm256_sub_pd(by, ay), abz = _mm256_sub_pd(bz, az);
    const V acx = _mm256_sub_pd(cx, ax), acy = _mm256_sub_pd(cy, ay), acz = _mm256_sub_pd(cz, az);
    const V bcx = _mm256_sub_pd(cx, bx), bcy = _mm256_sub_pd(cy, by), bcz = _mm256_sub_pd(cz, bz);
    const V nx = _mm256_sub_pd(_mm256_mul_pd(aby, acz), _mm256_mul_pd(abz, acy));
    const V ny = _mm256_sub_pd(_mm256_mul_pd(abz, acx), _mm256_mul_pd(abx, acz));
    const V nz = _mm256_sub_pd(_mm256_mul_pd(abx, acy), _mm256_mul_pd(aby, acx));
    alignas(32) double a[4];
    _mm256_store_pd(a, _mm256_mul_pd(_mm256_set1_pd(0.5), _mm256_sqrt_pd(squaredNorms(nx, ny, nz))));
    area += a[0];
    area += a[1];
    area += a[2];
    area += a[3];
    edge2 = _mm256_max_pd(edge2, _mm256_max_pd(_mm256_max_pd(squaredNorms(abx, aby, abz), squaredNorms(acx, acy, acz)),
                                               squaredNorms(bcx, bcy, bcz)));
  }
  alignas(32) double e[4];
  _mm256_store_pd(e, edge2);
  _mm256_zeroupper();  // as in collectMeetsAvx2: the SSE code after it runs with a clean state
  max_edge2 = std::max({e[0], e[1], e[2], e[3]});
  // The last triangles one at a time, from the table as above.
  for (; k < end; ++k) {
    const auto at = [&](std::size_t j) {
      const Index i = ch.corners[3 * k + j];
      return Vec3(tx[i], ty[i], tz[i]);
    };
    measureTriangle(at(0), at(1), at(2), area, max_edge2);
  }
}

/// Four and three AVX registers' worth of doubles, aligned as a register (a std::vector of
/// std::array<__m256d, N> would be aligned by malloc's 16 bytes: the attribute is dropped there).
struct alignas(32) Lanes4 {
  __m256d v[4];
};
struct alignas(32) Lanes3 {
  __m256d v[3];
};

/// The rest fit's running sums over one run of a region's own vertices (RestFitPass's).
struct RestRunAvx2 {
  __m256d sum_x, sum_d, xr[3];  ///< Σ x, Σ d, the columns Σ x·rest_j of Σ x restᵀ
  double moved;
};

[[gnu::target("avx2")]] inline void clearRun(RestRunAvx2& run) {
  run.sum_x = run.sum_d = run.xr[0] = run.xr[1] = run.xr[2] = _mm256_setzero_pd();
  run.moved = 0.0;
}

/// Adds a run's sums to its region and to the body's, as RestFitPass::flush does.
[[gnu::target("avx2")]] inline void flushRun(RestFit& f, Index region, RestRunAvx2& run) {
  alignas(32) double a[4];
  _mm256_store_pd(a, run.sum_d);
  f.sum_motion += Vec3(a[0], a[1], a[2]);
  f.moved += run.moved;
  if (region != kInvalidIndex) {
    _mm256_store_pd(a, run.sum_x);
    f.region_sum_x[region] += Vec3(a[0], a[1], a[2]);
    Eigen::Matrix3d m;
    for (int j = 0; j < 3; ++j) {
      _mm256_store_pd(a, run.xr[j]);
      m.col(j) = Vec3(a[0], a[1], a[2]);
    }
    f.region_xr[region] += m;
  }
  clearRun(run);
}

/// y = x − R·p, R given by its columns (lane 3 zero): the operations of Eigen's x − R * p, lane by
/// lane, (R₀p₀ + R₁p₁) + R₂p₂, so the same bits.
[[gnu::target("avx2")]] inline __m256d restOffset(const __m256d* cols, __m256d x, const __m256d* p) {
  const __m256d rp = _mm256_add_pd(_mm256_add_pd(_mm256_mul_pd(cols[0], p[0]), _mm256_mul_pd(cols[1], p[1])),
                                   _mm256_mul_pd(cols[2], p[2]));
  return _mm256_sub_pd(x, rp);
}

/// A rest position's three coordinates (single precision, as RestShape keeps Bullet's), each
/// widened to double (exactly) in all four lanes.
[[gnu::target("avx2")]] inline void broadcastRest(const float* p, __m256d* out) {
  for (int j = 0; j < 3; ++j) out[j] = _mm256_set1_pd(static_cast<double>(p[j]));
}

/// streamBoxesFloat with the rest-shape bound's part of the pass (RestFitPass's work), for
/// single-precision positions with previous ones and the radius bound: the boxes as
/// streamBoxesFloat makes them, and the y-boxes, the displacement boxes and the sums as
/// RestFitPass makes them, in double, a vertex's three coordinates at a time (AVX2, chosen at run
/// time), with RestFitPass's operations in its order: the same bits
/// (`ForeignChunks.RestFitPassGivesTheSameBitsWithAndWithoutAvx2`). On 8 tori × 50,000 vertices
/// with self-collision the refit took 8.8 ms a step through RestFitPass and 5.4 here, against 2.5
/// without self-collision (docs/DECISIONS.md, "Stop 32"). The second foreign slot behind a branch
/// (as in streamBoxesFloatLoop): 5.97–6.27 → 5.61–5.72 ms (`psc_demo --scene tori_pile --bodies 8
/// --resolution 50000 --steps 40 --pipeline sensors --truth none --no-penetration
/// --self-collision`, two alternating runs, docs/DECISIONS.md "Stop 35").
template <typename Slot>
[[gnu::target("avx2")]] bool streamBoxesFloatRestFit(const ChunkLists& ch, const char* base, std::size_t stride,
                                                     const char* prev, std::size_t prev_stride,
                                                     std::vector<MotionBox>& boxes, std::vector<OwnBox>& own_boxes,
                                                     float* copy, RestFit& f, const float* rest) {
  const std::size_t n = ch.vertexCount(), chunks = ch.count(), regions = f.rot.size();
  const std::uint8_t* slots = ch.foreign.slotData();
  assert(ch.owner.width() == sizeof(Slot) && ch.foreign.slotWidth() == sizeof(Slot));
  // Per chunk: the packed own and borrowed boxes (and the thrown-away borrowed one past the last,
  // which empty slots name, as for the y-boxes), and in double the y-box (lo, hi) and the box of
  // its own vertices' displacements (lo, hi), lane 3 unused; per region R's columns.
  thread_local std::vector<PackedBox> box, borrowed;
  thread_local std::vector<Lanes4> ybox;
  thread_local std::vector<Lanes3> cols;
  const __m256d dinf = _mm256_set1_pd(std::numeric_limits<double>::infinity());
  const __m256d ninf = _mm256_set1_pd(-std::numeric_limits<double>::infinity());
  box.assign(chunks, emptyPackedBox());
  borrowed.assign(chunks + 1, emptyPackedBox());
  ybox.assign(chunks + 1, Lanes4{{dinf, ninf, dinf, ninf}});
  cols.resize(regions);
  for (std::size_t r = 0; r < regions; ++r)
    for (int j = 0; j < 3; ++j) cols[r].v[j] = _mm256_setr_pd(f.rot[r](0, j), f.rot[r](1, j), f.rot[r](2, j), 0.0);
  const bool prev_apart = prefetchApart(base, stride, prev, prev_stride);
  // Raw pointers: the intrinsics' vector types may alias anything, so the vectors' own data
  // pointers would otherwise be read again after every store.
  PackedBox* const bx = box.data();
  PackedBox* const bb = borrowed.data();
  Lanes4* const yb = ybox.data();
  const Lanes3* const rc = cols.data();
  const Index* const region_of = ch.region_of.data();
  const std::uint8_t* const owner = ch.owner.data();
  const auto none = static_cast<Slot>(ch.foreign.none());
  RestRunAvx2 run;
  clearRun(run);
  Index run_region = kInvalidIndex;
  __m128 nan = _mm_setzero_ps();
  for (std::size_t v = 0; v < n; ++v) {
    __builtin_prefetch(base + (v + 24) * stride);
    if (prev_apart) __builtin_prefetch(prev + (v + 24) * prev_stride);
    Slot c;
    std::memcpy(&c, owner + sizeof(Slot) * v, sizeof c);
    if (c == none) continue;  // in no chunk (a vertex of no region)
    const float* p = reinterpret_cast<const float*>(base + v * stride);
    if (copy != nullptr) std::memcpy(copy + 3 * v, p, 3 * sizeof(float));
    const __m128 xv = loadPoint(p);  // (x, y, z, 0)
    nan = _mm_or_ps(nan, _mm_cmpunord_ps(xv, xv));
    const __m128 qv = loadPoint(reinterpret_cast<const float*>(prev + v * prev_stride));
    nan = _mm_or_ps(nan, _mm_cmpunord_ps(qv, qv));
    growPacked(bx[c], xv, withMotion(xv, qv));
    Slot fs[2];
    std::memcpy(fs, slots + 2 * sizeof(Slot) * v, sizeof fs);
    // The second slot behind a branch, as in streamBoxesFloatLoop (one vertex in ten has one).
    const int foreign = fs[1] != none ? 2 : 1;
    growPacked(bb[fs[0]], xv, xv);
    if (foreign == 2) growPacked(bb[fs[1]], xv, xv);
    // The rest fit in double: x, q and d = x − q exactly (a difference of two floats fits).
    const __m256d x4 = _mm256_cvtps_pd(xv);
    const __m256d d4 = _mm256_sub_pd(x4, _mm256_cvtps_pd(qv));
    const Index r = region_of[c];
    if (r != run_region) {
      flushRun(f, run_region, run);
      run_region = r;
    }
    __m256d* own = yb[c].v;
    own[2] = _mm256_min_pd(own[2], d4);
    own[3] = _mm256_max_pd(own[3], d4);
    run.sum_d = _mm256_add_pd(run.sum_d, d4);
    run.moved += 1.0;
    __m256d rp[3];
    broadcastRest(rest + 3 * v, rp);
    const __m256d y4 = restOffset(rc[r].v, x4, rp);
    own[0] = _mm256_min_pd(own[0], y4);
    own[1] = _mm256_max_pd(own[1], y4);
    run.sum_x = _mm256_add_pd(run.sum_x, x4);
    run.xr[0] = _mm256_add_pd(run.xr[0], _mm256_mul_pd(x4, rp[0]));
    run.xr[1] = _mm256_add_pd(run.xr[1], _mm256_mul_pd(x4, rp[1]));
    run.xr[2] = _mm256_add_pd(run.xr[2], _mm256_mul_pd(x4, rp[2]));
    for (int k = 0; k < foreign; ++k) {
      const Slot s = fs[k];
      // The thrown-away box past the last chunk takes any rotation: the vertex's own.
      const Index rf = s < chunks ? region_of[s] : r;
      __m256d yf = y4;
      if (__builtin_expect(rf != r, 0)) yf = restOffset(rc[rf].v, x4, rp);
      yb[s].v[0] = _mm256_min_pd(yb[s].v[0], yf);
      yb[s].v[1] = _mm256_max_pd(yb[s].v[1], yf);
    }
  }
  flushRun(f, run_region, run);
  // The rare third and later foreign chunks of a vertex.
  for (const auto& [v, fc] : ch.foreign.extra()) {
    const __m128 xv = loadPoint(reinterpret_cast<const float*>(base + std::size_t{v} * stride));
    growPacked(bb[fc], xv, xv);
    __m256d rp[3];
    broadcastRest(rest + 3 * std::size_t{v}, rp);
    const __m256d yf = restOffset(rc[region_of[fc]].v, _mm256_cvtps_pd(xv), rp);
    yb[fc].v[0] = _mm256_min_pd(yb[fc].v[0], yf);
    yb[fc].v[1] = _mm256_max_pd(yb[fc].v[1], yf);
  }
  const bool finite = finishPackedBoxes(bx, bb, chunks, _mm_movemask_ps(nan) != 0, boxes, own_boxes);
  for (std::size_t c = 0; c < chunks; ++c) {
    alignas(32) double a[4];
    Vec3* const into[4] = {&f.chunk_lo[c], &f.chunk_hi[c], &f.move_lo[c], &f.move_hi[c]};
    for (int k = 0; k < 4; ++k) {
      _mm256_store_pd(a, yb[c].v[k]);
      *into[k] = Vec3(a[0], a[1], a[2]);
    }
  }
  return finite;
}

#endif

/// The rest-shape bound's set-up (rest spheres, region rest centroids; rotations to identity) when
/// the body has none (its rest shape or chunks changed: Body::rest_fit was dropped), and the
/// per-step part's reset before the pass.
void startRestFit(Body& b) {
  const ChunkLists& ch = b.chunks;
  const std::size_t regions = b.regionCount(), chunks = ch.count();
  if (!b.rest_fit || b.rest_fit->region_count.size() != regions || b.rest_fit->chunk_rest_radius.size() != chunks) {
    b.rest_fit = std::make_unique<RestFit>();
    RestFit& f = *b.rest_fit;
    f.region_count.assign(regions, 0.0);
    f.region_rest_mean.assign(regions, Vec3::Zero());
    f.chunk_rest_center.resize(chunks);
    f.chunk_rest_radius.resize(chunks);
    f.region_rest_center.resize(regions);
    f.region_rest_radius.resize(regions);
    for (Index r = 0; r < regions; ++r) {
      Vec3 rlo = Vec3::Constant(std::numeric_limits<double>::infinity()), rhi = -rlo;
      for (Index c = ch.region_begin[r]; c < ch.region_begin[r + 1]; ++c) {
        for (Index v : ch.vertices(c)) {
          f.region_rest_mean[r] += b.rest[v];
          f.region_count[r] += 1.0;
        }
        Vec3 lo = Vec3::Constant(std::numeric_limits<double>::infinity()), hi = -lo;
        for (Index at = ch.table_begin[c]; at < ch.table_begin[c + 1]; ++at) {
          lo = lo.cwiseMin(b.rest[ch.table[at]]);
          hi = hi.cwiseMax(b.rest[ch.table[at]]);
        }
        f.chunk_rest_center[c] = 0.5 * (lo + hi);
        f.chunk_rest_radius[c] = 0.5 * (hi - lo).norm();
        rlo = rlo.cwiseMin(lo);
        rhi = rhi.cwiseMax(hi);
      }
      if (f.region_count[r] > 0.0) f.region_rest_mean[r] /= f.region_count[r];
      f.region_rest_center[r] = 0.5 * (rlo + rhi);
      f.region_rest_radius[r] = 0.5 * (rhi - rlo).norm();
      if (rlo.x() <= rhi.x())
        f.rest_magnitude = std::max(f.rest_magnitude, rlo.cwiseAbs().cwiseMax(rhi.cwiseAbs()).norm());
    }
    f.next_rot.assign(regions, Eigen::Matrix3d::Identity());
  }
  RestFit& f = *b.rest_fit;
  f.filled = false;
  f.rot = f.next_rot;
  f.chunk_lo.assign(chunks, Vec3::Constant(std::numeric_limits<double>::infinity()));
  f.chunk_hi.assign(chunks, Vec3::Constant(-std::numeric_limits<double>::infinity()));
  f.region_sum_x.assign(regions, Vec3::Zero());
  f.region_xr.assign(regions, Eigen::Matrix3d::Zero());
  f.sum_motion.setZero();
  f.moved = 0.0;
  f.move_lo.assign(chunks, Vec3::Constant(std::numeric_limits<double>::infinity()));
  f.move_hi.assign(chunks, Vec3::Constant(-std::numeric_limits<double>::infinity()));
}

/// After the pass: each region's fit (the rotation that best carries its rest shape onto its
/// vertices now), each chunk's and region's y-box as centre and half diagonal, and the rotation
/// the next pass starts from: this fit turned once more by its turn since the last fit (a body
/// spinning at a steady rate is followed without lag). When the fit turned away from the rotation
/// the pass used by more than a tenth of a mean rest edge over the region's rest sphere (a sudden
/// turn, or the first step after a jump), the region's y-boxes are redone with the fit: a second
/// pass over that region's tables only.
void finishRestFit(Body& b) {
  RestFit& f = *b.rest_fit;
  const ChunkLists& ch = b.chunks;
  const std::size_t regions = b.regionCount(), chunks = ch.count();
  f.chunk_center.resize(chunks);
  f.chunk_half.resize(chunks);
  f.region_center.resize(regions);
  f.region_half.resize(regions);
  const bool first = f.fit.size() != regions;
  if (first) f.fit.assign(regions, Eigen::Matrix3d::Identity());
  const auto centreAndHalf = [](const Vec3& lo, const Vec3& hi, Vec3& centre, double& half) {
    if ((lo.array() <= hi.array()).all()) {
      centre = 0.5 * (lo + hi);
      half = 0.5 * (hi - lo).norm();
    } else {  // no vertex: nothing of it can be in a pair
      centre = Vec3::Zero();
      half = 0.0;
    }
  };
  const double tolerance = 0.1 * b.rest_mean_edge;
  for (Index r = 0; r < regions; ++r) {
    const double n = f.region_count[r];
    if (n > 0.0) {
      // Σ (x − c)(rest − ĉ)ᵀ = Σ x restᵀ − n c ĉᵀ.
      const Vec3 c = f.region_sum_x[r] / n;
      const Eigen::Matrix3d fit = bestRotation(f.region_xr[r] - n * c * f.region_rest_mean[r].transpose(), f.rot[r]);
      if ((fit - f.rot[r]).norm() * f.region_rest_radius[r] > tolerance) {
        f.rot[r] = fit;
        for (Index k = ch.region_begin[r]; k < ch.region_begin[r + 1]; ++k) {
          Vec3 lo = Vec3::Constant(std::numeric_limits<double>::infinity()), hi = -lo;
          for (Index at = ch.table_begin[k]; at < ch.table_begin[k + 1]; ++at) {
            const Index u = ch.table[at];
            const Vec3 y = b.positions[u] - fit * b.rest[u];
            lo = lo.cwiseMin(y);
            hi = hi.cwiseMax(y);
          }
          f.chunk_lo[k] = lo;
          f.chunk_hi[k] = hi;
        }
      }
      Eigen::Quaterniond next(first ? fit : Eigen::Matrix3d(fit * f.fit[r].transpose() * fit));
      next.normalize();
      f.next_rot[r] = next.toRotationMatrix();
      f.fit[r] = fit;
    }
    Vec3 rlo = Vec3::Constant(std::numeric_limits<double>::infinity()), rhi = -rlo;
    for (Index c = ch.region_begin[r]; c < ch.region_begin[r + 1]; ++c) {
      centreAndHalf(f.chunk_lo[c], f.chunk_hi[c], f.chunk_center[c], f.chunk_half[c]);
      rlo = rlo.cwiseMin(f.chunk_lo[c]);
      rhi = rhi.cwiseMax(f.chunk_hi[c]);
    }
    centreAndHalf(rlo, rhi, f.region_center[r], f.region_half[r]);
  }
  // The self motion term: every own vertex's displacement d lies in its chunk's box, so
  // selfMotion(d, mean) ≤ min(the chunk's largest |d|, the farthest corner of the box from mean).
  // The mean is over the vertices on triangles (psc::selfMotion): the pass summed every own vertex,
  // so the loose ones (a volumetric body's inner nodes) come off again, with the displacement the
  // pass took (x − q in double: exact for floats, and the same operation for doubles).
  if (f.moved > 0.0)
    for (const Index v : ch.loose) {
      f.sum_motion -= b.positions[v] - b.previous[v];
      f.moved -= 1.0;
    }
  f.mean_motion = f.moved > 0.0 ? Vec3(f.sum_motion / f.moved) : Vec3::Zero();
  // y = x − R·rest: R·rest rounds at |rest|, the difference at |x| too, and a deviation is the
  // difference of two such values (2^-52 each, with room to spare).
  const double x_magnitude = (b.body_box.lo.array() <= b.body_box.hi.array()).all()
                                 ? b.body_box.lo.cwiseAbs().cwiseMax(b.body_box.hi.cwiseAbs()).norm()
                                 : 0.0;
  f.rounding = 1e-14 * (x_magnitude + f.rest_magnitude);
  f.chunk_self_motion.resize(chunks);
  f.region_self_motion.assign(regions, 0.0);
  for (Index c = 0; c < chunks; ++c) {
    double bound = b.chunk_box[c].motion;
    if ((f.move_lo[c].array() <= f.move_hi[c].array()).all()) {
      const Vec3 far = (f.move_lo[c] - f.mean_motion).cwiseAbs().cwiseMax((f.move_hi[c] - f.mean_motion).cwiseAbs());
      bound = std::min(bound, far.norm() * (1.0 + 1e-12));
    }
    f.chunk_self_motion[c] = bound;
    f.region_self_motion[ch.region_of[c]] = std::max(f.region_self_motion[ch.region_of[c]], bound);
  }
  f.filled = true;
}

/// b.shape from the positions at `base` (`stride` bytes apart).
///
/// `full`: every chunk's area (b.shape.chunk_area), each region's the sum of its chunks' in their
/// order, and the longest edge of every triangle. Otherwise (a check after the body's partitioning
/// kept a full measure's chunk areas in b.chunk_area_ref): only every k-th chunk of a region is
/// read, k = its chunk count / `sample_chunks` (at least 1), and the region's area is their sum
/// now times the region's area over theirs at that measure, a ratio estimator: exact for a region
/// that stretches evenly, and the very sum, to the bit, where k is 1. max_edge is then the sampled
/// chunks'. `full` also where a sampled measure has no reference of the right size (refitBounds).
void measureRegions(Body& b, bool full, std::size_t sample_chunks, const char* base, std::size_t stride,
                    bool is_float) {
  const ChunkLists& ch = b.chunks;
  double max_edge2 = 0.0;
#if defined(PSC_HAVE_AVX2_PATH)
  const bool avx2 = is_float && useAvx2Probes();
#else
  const bool avx2 = false;
#endif
  thread_local std::vector<double> table;
  const auto chunkArea = [&](Index c) {
    double area = 0.0;
#if defined(PSC_HAVE_AVX2_PATH)
    if (avx2) {
      measureChunkAvx2(ch, c, base, stride, table, area, max_edge2);
      return area;
    }
#endif
    if (is_float)
      measureChunk<float>(ch, c, base, stride, area, max_edge2);
    else
      measureChunk<double>(ch, c, base, stride, area, max_edge2);
    return area;
  };
  if (full) {
    b.shape.chunk_area.resize(ch.count());
    for (Index r = 0; r < b.regionCount(); ++r) {
      double area = 0.0;
      for (Index c = ch.region_begin[r]; c < ch.region_begin[r + 1]; ++c) area += b.shape.chunk_area[c] = chunkArea(c);
      b.shape.region_area[r] = area;
    }
  } else {
    b.shape.chunk_area.clear();
    for (Index r = 0; r < b.regionCount(); ++r) {
      const Index first = ch.region_begin[r], end = ch.region_begin[r + 1];
      const std::size_t k = sample_chunks == 0 ? 1 : std::max<std::size_t>(1, (end - first) / sample_chunks);
      double now = 0.0, then = 0.0, whole = 0.0;
      for (Index c = first; c < end; c += static_cast<Index>(k)) {
        now += chunkArea(c);
        then += b.chunk_area_ref[c];
      }
      if (k == 1) {
        b.shape.region_area[r] = now;
        continue;
      }
      for (Index c = first; c < end; ++c) whole += b.chunk_area_ref[c];
      if (then > 0.0) {
        b.shape.region_area[r] = now * (whole / then);
      } else {  // the sample had no area at the reference: every chunk
        now = 0.0;
        for (Index c = first; c < end; ++c) now += chunkArea(c);
        b.shape.region_area[r] = now;
      }
    }
  }
  b.shape.max_edge = std::sqrt(max_edge2);
}

/// Calls `f` with a value of the unsigned type of `width` bytes (1, 2 or 4: ChunkLists::foreign's
/// slotWidth()), so that a pass templated on its slots' type is chosen in one place.
template <typename F>
auto bySlotType(unsigned width, F&& f) {
  if (width == 1) return f(std::uint8_t{});
  if (width == 2) return f(std::uint16_t{});
  return f(std::uint32_t{});
}

}  // namespace

void refitBounds(Body& b, Measure how, bool swept, bool rest_fit, bool paths) {
  paths = paths && !swept;
  const bool measure = how.kind != Measure::None;
  const ChunkLists& ch = b.chunks;
  const bool full = how.kind == Measure::Full || (measure && b.chunk_area_ref.size() != ch.count());
  b.region_box.assign(b.regionCount(), emptyBox());
  b.body_box = emptyBox();
  if (measure) {
    b.shape.region_area.assign(b.regionCount(), 0.0);
    b.shape.max_edge = 0.0;
  }
  const char* base = static_cast<const char*>(b.positions.data());
  const std::size_t stride = b.positions.strideBytes();
  // The previous view is read with the current one's scalar type; mixed types take the slow path.
  const bool same_type = b.previous.empty() || b.previous.scalar() == b.positions.scalar();
  const char* prev = b.previous.empty() || !same_type ? nullptr : static_cast<const char*>(b.previous.data());
  const std::size_t prev_stride = b.previous.strideBytes();
  const bool is_float = b.positions.scalar() == PositionView::Scalar::Float32;
  double sum = 0.0;
  // A full measure reads every triangle's corners. Read from the positions' own records (Bullet's
  // nodes, 256 bytes apart) they miss the cache about three times per triangle on a large body, so
  // the pass leaves a packed copy of the body's positions for it: 12 or 24 bytes per vertex, held
  // only during this call. A sampled measure reads its few chunks in place.
  std::vector<float> copy_f;
  std::vector<double> copy_d;
  if (full && is_float)
    copy_f.resize(3 * ch.vertexCount());
  else if (full)
    copy_d.resize(3 * ch.vertexCount());
  float* const cf = full && is_float ? copy_f.data() : nullptr;
  double* const cd = full && !is_float ? copy_d.data() : nullptr;
  rest_fit = rest_fit && !swept && b.selfCollides();
  // The packed passes (streamBoxesFloat, streamBoxesFloatRestFit) leave every box final, motions
  // and range check included, and keep the own-vertex boxes; the other passes grow boxes from
  // empty and leave that to the loop after them.
#if defined(PSC_HAVE_AVX2_PATH)
  // (A rest shape kept in double, positions switched to single precision since: the generic pass.)
  const bool packed_rest =
      rest_fit && is_float && !paths && prev != nullptr && b.rest.single() != nullptr && useAvx2Probes();
#else
  const bool packed_rest = false;
#endif
#if defined(__SSE2__)
  const bool packed = packed_rest || (!rest_fit && is_float && !swept && !paths);
#else
  const bool packed = false;
#endif
  if (!packed) {
    b.chunk_box.assign(ch.count(), emptyBox());
    b.chunk_own.clear();
  }
  bool packed_finite = true;
#if defined(PSC_HAVE_AVX2_PATH)
  if (packed_rest) {
    startRestFit(b);
    RestFit& f = *b.rest_fit;
    packed_finite = bySlotType(ch.foreign.slotWidth(), [&](auto slot) {
      return streamBoxesFloatRestFit<decltype(slot)>(ch, base, stride, prev, prev_stride, b.chunk_box, b.chunk_own, cf,
                                                     f, b.rest.single());
    });
  } else
#endif
  if (rest_fit) {
    startRestFit(b);
    RestFitPass pass(*b.rest_fit, ch, b.rest);
    if (is_float)
      streamBoxes<float>(ch, base, stride, prev, prev_stride, swept, paths, b.chunk_box, sum, pass, cf);
    else
      streamBoxes<double>(ch, base, stride, prev, prev_stride, swept, paths, b.chunk_box, sum, pass, cd);
    pass.flush();
  } else {
    if (b.rest_fit) b.rest_fit->filled = false;
    NoRestFit none;
#if defined(__SSE2__)
    if (packed) {
      packed_finite = bySlotType(ch.foreign.slotWidth(), [&](auto slot) {
        return streamBoxesFloat<decltype(slot)>(ch, base, stride, prev, prev_stride, b.chunk_box, b.chunk_own, cf);
      });
    } else
#endif
    if (is_float)
      streamBoxes<float>(ch, base, stride, prev, prev_stride, swept, paths, b.chunk_box, sum, none, cf);
    else
      streamBoxes<double>(ch, base, stride, prev, prev_stride, swept, paths, b.chunk_box, sum, none, cd);
  }
  bool finite = packed_finite && std::isfinite(sum);
  if (!packed) {
    for (MotionBox& box : b.chunk_box) {
      box.motion = std::sqrt(box.motion);
      // Finite but beyond kMaxCoordinate (a blown-up simulation) is rejected like NaN.
      finite = finite && box.lo.cwiseAbs().maxCoeff() <= kMaxCoordinate && box.hi.cwiseAbs().maxCoeff() <= kMaxCoordinate;
    }
  }
  if (!same_type && (swept || paths)) {
    for (std::size_t v = 0; v < ch.vertexCount(); ++v) {
      const Index own = ch.chunkOf(v);
      if (own == kInvalidIndex) continue;
      const Vec3 q = b.previous[static_cast<Index>(v)];
      sum += q.sum();
      const auto add = [&](Index c) {
        b.chunk_box[c].lo = b.chunk_box[c].lo.cwiseMin(q);
        b.chunk_box[c].hi = b.chunk_box[c].hi.cwiseMax(q);
      };
      add(own);
      ch.foreign.forEach(static_cast<Index>(v), add);
    }
    finite = finite && std::isfinite(sum);
  }
  if (!same_type && !swept) {
    for (std::size_t c = 0; c < ch.count(); ++c)
      for (Index v : ch.vertices(static_cast<Index>(c)))
        b.chunk_box[c].motion = std::max(b.chunk_box[c].motion, b.vertexMotion(v));
  }
  if (!finite) {
    checkFinite(b.positions, b.label());
    if (!b.previous.empty()) checkFinite(b.previous, b.label() + " (previous positions)");
  }
  if (measure) {
    // The measures' positions: the packed copy after a full pass, the records themselves otherwise.
    const char* mbase = cf != nullptr ? reinterpret_cast<const char*>(cf) : cd != nullptr ? reinterpret_cast<const char*>(cd) : base;
    const std::size_t mstride = cf != nullptr ? 3 * sizeof(float) : cd != nullptr ? 3 * sizeof(double) : stride;
    measureRegions(b, full, how.sample_chunks, mbase, mstride, is_float);
  }
  for (Index r = 0; r < b.regionCount(); ++r) {
    for (Index c = ch.region_begin[r]; c < ch.region_begin[r + 1]; ++c) grow(b.region_box[r], b.chunk_box[c]);
    grow(b.body_box, b.region_box[r]);
  }
  if (rest_fit) finishRestFit(b);
}

namespace {

/// An interval along a sweep axis and what it belongs to.
struct SweepItem {
  double lo, hi;
  Index id;
};

void sortItems(std::vector<SweepItem>& items) {
  std::sort(items.begin(), items.end(),
            [](const SweepItem& x, const SweepItem& y) { return x.lo != y.lo ? x.lo < y.lo : x.id < y.id; });
}

/// Sort and sweep between two sets: f(a, b) once for every pair whose intervals overlap.
/// O((|A| + |B|) log + pairs overlapping along the axis); deterministic (ties broken by id).
template <class F>
void sweepBetween(std::vector<SweepItem>& a, std::vector<SweepItem>& b, F&& f) {
  sortItems(a);
  sortItems(b);
  std::size_t i = 0, j = 0;
  while (i < a.size() && j < b.size()) {
    if (a[i].lo <= b[j].lo) {
      for (std::size_t k = j; k < b.size() && b[k].lo <= a[i].hi; ++k) f(a[i].id, b[k].id);
      ++i;
    } else {
      for (std::size_t k = i; k < a.size() && a[k].lo <= b[j].hi; ++k) f(a[k].id, b[j].id);
      ++j;
    }
  }
}

/// Sort and sweep within one set: f(a, b) once for every unordered pair (a ≠ b) whose intervals
/// overlap.
template <class F>
void sweepWithin(std::vector<SweepItem>& a, F&& f) {
  sortItems(a);
  for (std::size_t i = 0; i < a.size(); ++i)
    for (std::size_t k = i + 1; k < a.size() && a[k].lo <= a[i].hi; ++k) f(a[i].id, a[k].id);
}

/// The squared distance from p to the triangle (a, b, c), without a branch: the least of the
/// distances to the three edges and, where p projects inside the triangle, the distance to its
/// plane (the candidate filter's, and the self exclusion rule's at rest). Its AVX2 twin
/// (FilterDistance4) makes the same operations in the same order, so the two give the same bits and
/// the same candidates. Degenerate edges and triangles give the distance to their points, never NaN.
struct FilterDistance {
  static double dot(double ax, double ay, double az, double bx, double by, double bz) {
    return (ax * bx + ay * by) + az * bz;
  }
  /// Squared distance from the point at q (relative to the edge's start) to the edge e.
  static double edge(double ex, double ey, double ez, double qx, double qy, double qz, double ee, double qe) {
    const double t = ee > 0.0 ? std::min(std::max(qe / ee, 0.0), 1.0) : 0.0;
    const double x = qx - t * ex, y = qy - t * ey, z = qz - t * ez;
    return dot(x, y, z, x, y, z);
  }
  static double of(const Vec3& p, const Vec3& a, const Vec3& b, const Vec3& c) {
    const double abx = b.x() - a.x(), aby = b.y() - a.y(), abz = b.z() - a.z();
    const double acx = c.x() - a.x(), acy = c.y() - a.y(), acz = c.z() - a.z();
    const double apx = p.x() - a.x(), apy = p.y() - a.y(), apz = p.z() - a.z();
    const double bcx = c.x() - b.x(), bcy = c.y() - b.y(), bcz = c.z() - b.z();
    const double bpx = p.x() - b.x(), bpy = p.y() - b.y(), bpz = p.z() - b.z();
    const double d00 = dot(abx, aby, abz, abx, aby, abz), d11 = dot(acx, acy, acz, acx, acy, acz);
    const double d01 = dot(abx, aby, abz, acx, acy, acz);
    const double d20 = dot(apx, apy, apz, abx, aby, abz), d21 = dot(apx, apy, apz, acx, acy, acz);
    const double e22 = dot(bcx, bcy, bcz, bcx, bcy, bcz), e2p = dot(bpx, bpy, bpz, bcx, bcy, bcz);
    const double s = std::min(std::min(edge(abx, aby, abz, apx, apy, apz, d00, d20), edge(acx, acy, acz, apx, apy, apz, d11, d21)),
                              edge(bcx, bcy, bcz, bpx, bpy, bpz, e22, e2p));
    const double denom = d00 * d11 - d01 * d01, vn = d11 * d20 - d01 * d21, wn = d00 * d21 - d01 * d20;
    const double nx = aby * acz - abz * acy, ny = abz * acx - abx * acz, nz = abx * acy - aby * acx;
    const double nn = dot(nx, ny, nz, nx, ny, nz), np = dot(nx, ny, nz, apx, apy, apz);
    const bool inside = (denom > 0.0) & (nn > 0.0) & (vn >= 0.0) & (wn >= 0.0) & (vn + wn <= denom);
    return inside ? std::min(np * np / nn, s) : s;
  }
};

/// The sensor axis of one region pair: n from A's particle to B's, and each chunk's extent along
/// n (its box's support, grown by its reach).
struct Axis {
  bool valid = false;
  Vec3 n = Vec3::Zero();
  Vec3 abs_n = Vec3::Zero();
  double project(const Vec3& x) const { return n.dot(x); }
  // Extent of a box along n, without growth.
  void extent(const MotionBox& b, double& lo, double& hi) const {
    const Vec3 c = 0.5 * (b.lo + b.hi), h = 0.5 * (b.hi - b.lo);
    const double m = n.dot(c), r = abs_n.dot(h);
    lo = m - r;
    hi = m + r;
  }
};

struct ChunkRef {
  Index chunk;
  double lo_n, hi_n;  ///< extent along the sensor axis, without growth
  Grown box;
  // What the chunk pairs of one region pair read, gathered once per region pair on first use:
  int vertices_at = -1;   ///< offset of this chunk's vertex records in Scratch::verts
  int triangles_at = -1;  ///< offset of its triangle records in Scratch::tri_lanes
  /// Self pairs: the rest position its triangles' rest centroids are taken from (that of the first
  /// vertex of its table), so that they and the vertices' rest positions are compared as small
  /// differences, not at the coordinates' magnitude.
  Vec3 rest_origin = Vec3::Zero();
};

struct VertexRec {
  Vec3 x;
  double r;   ///< contact radius of the vertex: margin sum + motion term
  double xn;  ///< projection on the sensor axis
  Index v;
  double reach2;  ///< MotionBound::Radius: squared distance below which a triangle is kept (reachOf)
  double motion = 0.0;  ///< |x − previous| (PairContext::meeting)
};

/// What a probe tests against a triangle's box: the box [lo, hi] grown by r in every direction
/// (rounded: the distance between the two boxes at most r). A vertex's ball is lo = hi = its centre;
/// with MotionBound::Ahead the box of its path ahead with r = the margins.
struct Probe {
  Vec3 lo, hi;
  double r;
};

/// With MotionBound::Radius a pair is kept when the vertex lies within its radius r of the
/// triangle, by the exact distance in double. The exact stage may decide in single precision
/// (Bullet's CollideVF_SS): the slack keeps every pair whose float-rounded distance can fall
/// below r, i.e. a relative 1e-5 of r plus 1e-6 of the coordinates' magnitude (float's 6e-8 over
/// the dozen operations of a point-triangle distance).
double reachOf(const Vec3& x, double r) {
  const double reach = r * (1.0 + 1e-5) + 1e-6 * x.cwiseAbs().maxCoeff();
  return reach * reach;
}

/// One triangle's record as gatherTriangles builds it, before it goes into TriangleLanes: its box
/// and its extent along the sensor axis.
struct TriangleRec {
  Vec3 lo, hi;
  double nlo, nhi;  ///< extent along the sensor axis
  Vec3 rest_mid = Vec3::Zero();  ///< self pairs: the triangle's centroid in the rest shape, from ChunkRef::rest_origin
};

/// The rest, read only for the pairs whose boxes meet (parallel to Scratch::tri_lanes).
struct TriangleCorners {
  Vec3 a, b, c;  ///< corners at the current positions (the distance test with MotionBound::Radius)
  Index t;
  Index k;  ///< its place in the chunk lists (ChunkLists::triangle)
  double motion = 0.0;  ///< PairContext::meeting: the largest |corner − its previous position|
};

/// The gathered triangle records (gatherTriangles), as a structure of arrays parallel to
/// Scratch::corners: what the kept-triangle pass reads, four at a time with AVX2.
struct TriangleLanes {
  std::vector<double> lo_x, lo_y, lo_z, hi_x, hi_y, hi_z, n_lo, n_hi;
  std::vector<Vec3> rest_mid;  ///< self pairs: the triangle's centroid in the rest shape
  std::size_t size() const { return lo_x.size(); }
  void clear() {
    for (std::vector<double>* v : {&lo_x, &lo_y, &lo_z, &hi_x, &hi_y, &hi_z, &n_lo, &n_hi}) v->clear();
    rest_mid.clear();
  }
  /// Room for `n` more records; returns where they start (written with set, no check per record).
  std::size_t grow(std::size_t n) {
    const std::size_t at = size();
    for (std::vector<double>* v : {&lo_x, &lo_y, &lo_z, &hi_x, &hi_y, &hi_z, &n_lo, &n_hi}) v->resize(at + n);
    rest_mid.resize(at + n);
    return at;
  }
  void set(std::size_t k, const TriangleRec& tr) {
    lo_x[k] = tr.lo.x();
    lo_y[k] = tr.lo.y();
    lo_z[k] = tr.lo.z();
    hi_x[k] = tr.hi.x();
    hi_y[k] = tr.hi.y();
    hi_z[k] = tr.hi.z();
    n_lo[k] = tr.nlo;
    n_hi[k] = tr.nhi;
    rest_mid[k] = tr.rest_mid;
  }
};

/// The triangles of one chunk pair that its picked vertices can reach, as a structure of arrays:
/// the probe loop reads them four at a time (AVX2) or two (SSE2), without a branch per test.
struct KeptTriangles {
  std::vector<double> lo_x, lo_y, lo_z, hi_x, hi_y, hi_z, n_lo, n_hi;
  std::vector<double> mid_x, mid_y, mid_z;  ///< self pairs: rest centroids
  std::vector<Index> record;  ///< index into Scratch::tri_lanes / Scratch::corners
  std::vector<unsigned char> meets;  ///< per probe: 1 when the vertex's ball meets the triangle's box
  std::size_t size() const { return count_; }
  /// Empties the set, with room for `most` triangles and the padding (the arrays only grow: pushes
  /// write in place).
  void reset(std::size_t most) {
    count_ = 0;
    most += 3;
    if (record.size() >= most) return;
    for (std::vector<double>* v : {&lo_x, &lo_y, &lo_z, &hi_x, &hi_y, &hi_z, &n_lo, &n_hi, &mid_x, &mid_y, &mid_z})
      v->resize(most);
    record.resize(most);
    meets.resize(most);
  }
  /// Fills the set up to a multiple of four with boxes that meet nothing (empty, at +infinity and
  /// with an empty extent along the axis): the four-wide probe loop then needs no scalar tail.
  /// Returns the padded size; size() stays the count of real triangles.
  std::size_t pad() {
    const double inf = std::numeric_limits<double>::infinity();
    std::size_t j = count_;
    for (; j % 4 != 0; ++j) {
      lo_x[j] = lo_y[j] = lo_z[j] = n_lo[j] = inf;
      hi_x[j] = hi_y[j] = hi_z[j] = n_hi[j] = -inf;
    }
    return j;
  }
  /// Appends gathered triangle k of `t`.
  void push(const TriangleLanes& t, std::size_t k, bool self) {
    const std::size_t j = count_++;
    if (self) {
      mid_x[j] = t.rest_mid[k].x();
      mid_y[j] = t.rest_mid[k].y();
      mid_z[j] = t.rest_mid[k].z();
    }
    lo_x[j] = t.lo_x[k];
    lo_y[j] = t.lo_y[k];
    lo_z[j] = t.lo_z[k];
    hi_x[j] = t.hi_x[k];
    hi_y[j] = t.hi_y[k];
    hi_z[j] = t.hi_z[k];
    n_lo[j] = t.n_lo[k];
    n_hi[j] = t.n_hi[k];
    record[j] = static_cast<Index>(k);
  }

 private:
  std::size_t count_ = 0;
};

/// What the picking pass of chunkCandidates reads of each gathered vertex, as a structure of arrays
/// parallel to Scratch::verts (four vertices per instruction with AVX2).
struct VertexLanes {
  std::vector<double> x, y, z, r, n;
  void clear() {
    for (std::vector<double>* v : {&x, &y, &z, &r, &n}) v->clear();
  }
};

struct Scratch {
  std::vector<SweepItem> items_a, items_b;
  std::vector<ChunkRef> near_a, near_b;
  std::vector<VertexRec> verts;
  VertexLanes vert_lanes;
  TriangleLanes tri_lanes;
  std::vector<TriangleCorners> corners;
  KeptTriangles kept;
  std::vector<Index> hits;
  std::vector<Index> picked;  ///< chunkCandidates: the vertices of a chunk pair worth probing
  /// chunkCandidates with MotionBound::Radius: the pairs whose boxes meet, (vertex record,
  /// triangle record), whose exact distance is then measured four at a time.
  std::vector<std::pair<Index, Index>> pending;
  /// gatherTriangles: the positions of a chunk's table (and the other end of their paths).
  std::vector<Vec3> table_now, table_other;
  /// Forgets the gathered vertex and triangle records (ChunkRef's offsets must be reset with them).
  void clearRecords() {
    verts.clear();
    vert_lanes.clear();
    tri_lanes.clear();
    corners.clear();
  }
};

struct PairContext {
  const Body& vb;
  const Body& tb;
  double margin_sum;      ///< the contact radius without motion: margin_A + margin_B, or the self radius
  double triangle_share;  ///< the triangle side's part of margin_sum (its boxes' growth)
  double motion_factor;
  bool swept;
  const Axis& axis;
  std::vector<std::uint64_t>& out;
  StepStats& counters;
  Scratch& s;
  double self_exclude2 = -1.0;  ///< vb == tb: squared rest distance below which a pair is excluded
  /// vb == tb with the self motion term (RestFit::mean_motion): a vertex's motion term is
  /// selfMotion of its displacement against it.
  const Vec3* self_mean_motion = nullptr;
  /// MotionBound::Ahead (two-body pairs): the probes test the paths `ahead_steps` ahead, the exact
  /// distance the radius. 0: not Ahead.
  double ahead_steps = 0.0;
  /// SensorSettings::nearest_candidates: each candidate's squared distance, parallel to `out`, and
  /// per vertex of vb (by id) the least squared distance kept so far (+infinity: none yet).
  std::vector<double>* out_d2 = nullptr;
  double* best2 = nullptr;
  /// With out_d2: each candidate's owned-triangle index in tb's chunks, parallel to `out`
  /// (NearestSeeds).
  std::vector<Index>* out_k = nullptr;
  /// vb == tb with the rest-shape bound on: this step's y-boxes, for dropUnbentPicks.
  const RestFit* rest_fit = nullptr;
  /// CullParams::meeting (two-body pairs): the triangles' boxes hold their paths, and a pair is
  /// also kept within margin_sum + |Δx_v| + the triangle's largest corner motion.
  bool meeting = false;
};

/// SensorSettings::nearest_candidates keeps a vertex's candidates within this factor of its least
/// squared distance (a relative 1e-4 on the distance, rounded up).
constexpr double kNearestBand2 = 1.0 + 2.1e-4;

/// The distance past which no box can hold a triangle in the band of a vertex whose nearest so far
/// is at squared distance `best2` (a little wider than the band, for the rounding of the box
/// distance against the exact one); +infinity while there is none.
inline double nearestBand(double best2) { return std::sqrt(best2 * (kNearestBand2 + 1e-5)); }

/// Self-collision's exclusion rule: the triangle holds the vertex, or the two were within the
/// exclusion distance in the body's rest shape.
/// A corner of the triangle within the distance settles most pairs without the distance to the
/// triangle (which is at most that corner's).
bool excludedSelfPair(const PairContext& ctx, Index v, const Triangle& tri) {
  if (tri[0] == v || tri[1] == v || tri[2] == v) return true;
  const RestShape& rest = ctx.tb.rest;
  const Vec3 p = rest[v];
  const Vec3 a = rest[tri[0]], b = rest[tri[1]], c = rest[tri[2]];
  const double e2 = ctx.self_exclude2;
  if ((a - p).squaredNorm() < e2 || (b - p).squaredNorm() < e2 || (c - p).squaredNorm() < e2) return true;
  return FilterDistance::of(p, a, b, c) < e2;
}

void gatherVertices(const PairContext& ctx, ChunkRef& c) {
  if (c.vertices_at >= 0) return;
  c.vertices_at = static_cast<int>(ctx.s.verts.size());
  const bool moved = !ctx.vb.previous.empty();
  const bool swept = ctx.swept && moved;
  const bool self_motion = ctx.self_mean_motion != nullptr && moved;
  const IndexRange list = ctx.vb.chunks.vertices(c.chunk);
  // Sized once, then written in place (no capacity check per push).
  const std::size_t at = ctx.s.verts.size(), n = list.size();
  ctx.s.verts.resize(at + n);
  VertexLanes& lanes = ctx.s.vert_lanes;
  for (std::vector<double>* l : {&lanes.x, &lanes.y, &lanes.z, &lanes.r, &lanes.n}) l->resize(at + n);
  for (std::size_t k = 0; k < n; ++k) {
    const Index v = list[k];
    Vec3 x = ctx.vb.positions[v];
    const Vec3 q = moved ? ctx.vb.previous[v] : x;
    // Body::vertexMotion, or the self motion term.
    const double motion = self_motion ? selfMotion(x - q, *ctx.self_mean_motion) : moved ? (x - q).norm() : 0.0;
    double r = ctx.margin_sum + ctx.motion_factor * motion;
    if (swept) {
      // The ball about the path's midpoint with half its length holds the whole path.
      r = ctx.margin_sum + 0.5 * (x - q).norm();
      x = 0.5 * (x + q);
    }
    const double xn = ctx.axis.valid ? ctx.axis.project(x) : 0.0;
    // A self pair's radius is the self rule's (R + 2·selfMotion), not what Bullet's test accepts
    // (R + 2·|Δx|, at least as far): no rounding slack, or the exact stage would make contacts
    // beyond the rule (seen in the double build, where the truth's rounding band is too narrow to
    // hide them).
    const double reach2 = swept ? 0.0 : ctx.self_exclude2 >= 0.0 ? r * r : reachOf(x, r);
    // Meeting pairs: the vertex's probes reach at least its own path (margins + |Δx|), whatever
    // motion_factor the radius bound has.
    const double path = ctx.meeting && moved ? (x - q).norm() : 0.0;
    if (ctx.meeting) r = std::max(r, ctx.margin_sum + path);
    // nearest_candidates: the probes need not reach past the band of the vertex's nearest so far
    // (the same bound chunkCandidates puts on each probe), so neither do the picking and the
    // kept-triangle box.
    if (ctx.best2 != nullptr && ctx.ahead_steps == 0.0) r = std::min(r, nearestBand(ctx.best2[v]));
    ctx.s.verts[at + k] = {x, r, xn, v, reach2, path};
    lanes.x[at + k] = x.x();
    lanes.y[at + k] = x.y();
    lanes.z[at + k] = x.z();
    lanes.r[at + k] = r;
    lanes.n[at + k] = xn;
  }
  ctx.counters.candidate_vertices += n;
}

void gatherTriangles(const PairContext& ctx, ChunkRef& c) {
  if (c.triangles_at >= 0) return;
  c.triangles_at = static_cast<int>(ctx.s.tri_lanes.size());
  const ChunkLists& ch = ctx.tb.chunks;
  const bool swept = ctx.swept && !ctx.tb.previous.empty();
  const bool ahead = ctx.ahead_steps > 0.0 && !ctx.tb.previous.empty();
  const bool meeting = ctx.meeting && !ctx.tb.previous.empty();
  const bool paths = swept || ahead || meeting;
  // Each vertex of the chunk's table read once (from the body's positions, usually Bullet's
  // 256-byte nodes), not once per triangle corner: about 45 reads for a chunk's 64 triangles
  // instead of 192. With Swept, Ahead or meeting pairs, the other end of each corner's path beside it.
  const Index* table = ch.table.data() + ch.table_begin[c.chunk];
  const std::size_t n_table = ch.table_begin[c.chunk + 1] - ch.table_begin[c.chunk];
  if (ctx.self_exclude2 >= 0.0 && n_table > 0) c.rest_origin = ctx.tb.rest[table[0]];
  std::vector<Vec3>& at_now = ctx.s.table_now;
  std::vector<Vec3>& at_other = ctx.s.table_other;
  at_now.resize(n_table);
  for (std::size_t j = 0; j < n_table; ++j) at_now[j] = ctx.tb.positions[table[j]];
  if (paths) {
    at_other.resize(n_table);
    for (std::size_t j = 0; j < n_table; ++j) {
      const Vec3 q = ctx.tb.previous[table[j]];
      // Swept and meeting pairs: the triangle's swept volume lies in the box of its six positions
      // (now and before). Ahead: the box of its corners now and ahead_steps steps ahead.
      at_other[j] = ahead ? Vec3(at_now[j] + ctx.ahead_steps * (at_now[j] - q)) : q;
    }
  }
  const std::size_t first = ch.triangle_begin[c.chunk];
  const std::size_t out = ctx.s.tri_lanes.grow(ch.triangle_begin[c.chunk + 1] - first);
  ctx.s.corners.resize(out + ch.triangle_begin[c.chunk + 1] - first);
  for (std::size_t at = first; at < ch.triangle_begin[c.chunk + 1]; ++at) {
    const Index la = ch.corners[3 * at], lb = ch.corners[3 * at + 1], lc = ch.corners[3 * at + 2];
    const Vec3 &a = at_now[la], &b = at_now[lb], &cc = at_now[lc];
    TriangleRec rec{a.cwiseMin(b).cwiseMin(cc), a.cwiseMax(b).cwiseMax(cc), 0.0, 0.0};
    if (ctx.self_exclude2 >= 0.0) {
      // From the chunk's origin: exact differences for a rest shape in single precision.
      const Vec3& o = c.rest_origin;
      rec.rest_mid = ((ctx.tb.rest[table[la]] - o) + (ctx.tb.rest[table[lb]] - o) + (ctx.tb.rest[table[lc]] - o)) / 3.0;
    }
    if (ctx.axis.valid) {
      const double pa = ctx.axis.project(a), pb = ctx.axis.project(b), pc = ctx.axis.project(cc);
      rec.nlo = std::min(pa, std::min(pb, pc));
      rec.nhi = std::max(pa, std::max(pb, pc));
    }
    double corner_motion = 0.0;
    if (paths) {
      for (const Index l : {la, lb, lc}) {
        if (meeting) corner_motion = std::max(corner_motion, (at_now[l] - at_other[l]).norm());
        const Vec3& p = at_other[l];
        rec.lo = rec.lo.cwiseMin(p);
        rec.hi = rec.hi.cwiseMax(p);
        if (ctx.axis.valid) {
          const double pp = ctx.axis.project(p);
          rec.nlo = std::min(rec.nlo, pp);
          rec.nhi = std::max(rec.nhi, pp);
        }
      }
    }
    ctx.s.tri_lanes.set(out + (at - first), rec);
    ctx.s.corners[out + (at - first)] = {a, b, cc, ch.triangleId(c.chunk, at), static_cast<Index>(at), corner_motion};
  }
  ctx.counters.candidate_triangles += ch.triangleCount(c.chunk);
}

/// The scalar test of kept triangle j (the vector loops' tail): the probe (the vertex's ball, or the
/// rounded box of its path ahead) meets its box and [n_lo, n_hi] meets its extent along the sensor axis.
bool meetsScalar(const KeptTriangles& kept, std::size_t j, const Probe& pr, double n_lo, double n_hi) {
  const double r2 = pr.r * pr.r;
  const double dx = std::max(0.0, std::max(kept.lo_x[j] - pr.hi.x(), pr.lo.x() - kept.hi_x[j]));
  const double dy = std::max(0.0, std::max(kept.lo_y[j] - pr.hi.y(), pr.lo.y() - kept.hi_y[j]));
  const double dz = std::max(0.0, std::max(kept.lo_z[j] - pr.hi.z(), pr.lo.z() - kept.hi_z[j]));
  return dx * dx + dy * dy + dz * dz <= r2 && n_hi >= kept.n_lo[j] && n_lo <= kept.n_hi[j];
}

/// Pass 2: the records of the triangles marked in `meets`, in kept order, into `hits`; returns how
/// many (a store per triangle and no branch).
std::size_t gatherMarked(const KeptTriangles& kept, const unsigned char* meets, Index* hits) {
  std::size_t n_hits = 0;
  const Index* record = kept.record.data();
  for (std::size_t k = 0; k < kept.size(); ++k) {
    hits[n_hits] = record[k];
    n_hits += meets[k];
  }
  return n_hits;
}

/// The kept triangles whose box the vertex's ball meets and whose extent along the sensor axis
/// meets the vertex's [n_lo, n_hi], into `hits` (their records, in kept order); returns how many.
/// Two triangles per instruction without a branch per test: about one triangle in ten passes
/// between two bodies, and a branch on each would be mispredicted, so pass 1 marks (`meets`) and
/// pass 2 gathers (a running count inside the vector loop would chain every iteration to the one
/// before: measured slower). With kSelf a triangle whose rest centroid lies within the exclusion
/// distance of the vertex's rest position does not pass either (the triangle was at least as close,
/// so the rule excludes the pair). Most self pairs the boxes keep are such neighbours, so passes
/// are rare there and the loop gathers at once behind a branch that is almost never taken.
template <bool kSelf>
std::size_t collectMeets(const KeptTriangles& kept, const Probe& pr, double n_lo, double n_hi, const Vec3& rest,
                         double exclude2, unsigned char* meets, Index* hits) {
  const std::size_t m = kept.size();
  const Index* record = kept.record.data();
  const double *gx = kept.mid_x.data(), *gy = kept.mid_y.data(), *gz = kept.mid_z.data();
  std::size_t j = 0, n_hits = 0;
  int any = 0;
#if defined(__SSE2__)
  // SSE2 is part of x86-64; the same tests as meetsScalar.
  {
    const double r2 = pr.r * pr.r;
    const double *lx = kept.lo_x.data(), *ly = kept.lo_y.data(), *lz = kept.lo_z.data();
    const double *hx = kept.hi_x.data(), *hy = kept.hi_y.data(), *hz = kept.hi_z.data();
    const double *tnl = kept.n_lo.data(), *tnh = kept.n_hi.data();
    const __m128d lox = _mm_set1_pd(pr.lo.x()), loy = _mm_set1_pd(pr.lo.y()), loz = _mm_set1_pd(pr.lo.z());
    const __m128d hix = _mm_set1_pd(pr.hi.x()), hiy = _mm_set1_pd(pr.hi.y()), hiz = _mm_set1_pd(pr.hi.z());
    const __m128d vr2 = _mm_set1_pd(r2);
    const __m128d vnl = _mm_set1_pd(n_lo), vnh = _mm_set1_pd(n_hi), zero = _mm_setzero_pd();
    const __m128d px = _mm_set1_pd(rest.x()), py = _mm_set1_pd(rest.y()), pz = _mm_set1_pd(rest.z());
    const __m128d e2 = _mm_set1_pd(exclude2);
    for (; j + 2 <= m; j += 2) {
      const __m128d dx = _mm_max_pd(zero, _mm_max_pd(_mm_sub_pd(_mm_loadu_pd(lx + j), hix), _mm_sub_pd(lox, _mm_loadu_pd(hx + j))));
      const __m128d dy = _mm_max_pd(zero, _mm_max_pd(_mm_sub_pd(_mm_loadu_pd(ly + j), hiy), _mm_sub_pd(loy, _mm_loadu_pd(hy + j))));
      const __m128d dz = _mm_max_pd(zero, _mm_max_pd(_mm_sub_pd(_mm_loadu_pd(lz + j), hiz), _mm_sub_pd(loz, _mm_loadu_pd(hz + j))));
      const __m128d d2 = _mm_add_pd(_mm_add_pd(_mm_mul_pd(dx, dx), _mm_mul_pd(dy, dy)), _mm_mul_pd(dz, dz));
      __m128d ok = _mm_and_pd(_mm_cmple_pd(d2, vr2), _mm_and_pd(_mm_cmpge_pd(vnh, _mm_loadu_pd(tnl + j)),
                                                                _mm_cmple_pd(vnl, _mm_loadu_pd(tnh + j))));
      if constexpr (kSelf) {
        const __m128d ex = _mm_sub_pd(_mm_loadu_pd(gx + j), px), ey = _mm_sub_pd(_mm_loadu_pd(gy + j), py);
        const __m128d ez = _mm_sub_pd(_mm_loadu_pd(gz + j), pz);
        const __m128d g2 = _mm_add_pd(_mm_add_pd(_mm_mul_pd(ex, ex), _mm_mul_pd(ey, ey)), _mm_mul_pd(ez, ez));
        ok = _mm_and_pd(ok, _mm_cmpge_pd(g2, e2));
        const int mask = _mm_movemask_pd(ok);
        if (mask != 0) {
          if (mask & 1) hits[n_hits++] = record[j];
          if (mask & 2) hits[n_hits++] = record[j + 1];
        }
      } else {
        const int mask = _mm_movemask_pd(ok);
        any |= mask;
        meets[j] = static_cast<unsigned char>(mask & 1);
        meets[j + 1] = static_cast<unsigned char>(mask >> 1);
      }
    }
  }
#endif
  for (; j < m; ++j) {
    const bool ok = meetsScalar(kept, j, pr, n_lo, n_hi);
    if constexpr (kSelf) {
      if (ok && (Vec3(gx[j], gy[j], gz[j]) - rest).squaredNorm() >= exclude2) hits[n_hits++] = record[j];
    } else {
      any |= static_cast<int>(ok);
      meets[j] = ok;
    }
  }
  if constexpr (!kSelf) return any == 0 ? 0 : gatherMarked(kept, meets, hits);
  return n_hits;
}

#if defined(PSC_HAVE_AVX2_PATH)
/// Per four-lane mask, the passing lanes first in order (the rest of each row: lane 0, harmless,
/// overwritten or past the count).
constexpr std::array<std::array<std::uint8_t, 4>, 16> kLeftPack = {{
    {0, 0, 0, 0}, {0, 0, 0, 0}, {1, 0, 0, 0}, {0, 1, 0, 0}, {2, 0, 0, 0}, {0, 2, 0, 0}, {1, 2, 0, 0}, {0, 1, 2, 0},
    {3, 0, 0, 0}, {0, 3, 0, 0}, {1, 3, 0, 0}, {0, 1, 3, 0}, {2, 3, 0, 0}, {0, 2, 3, 0}, {1, 2, 3, 0}, {0, 1, 2, 3}}};

/// The probe of collectMeets, four kept triangles at a time (AVX2): the same operations in the same
/// order as its SSE2 loop, without fused multiply-adds, so the same triangles pass.
struct ProbeLanes {
  __m256d lox, loy, loz, hix, hiy, hiz, r2, n_lo, n_hi;
  [[gnu::target("avx2")]] ProbeLanes(const Probe& pr, double nl, double nh)
      : lox(_mm256_set1_pd(pr.lo.x())), loy(_mm256_set1_pd(pr.lo.y())), loz(_mm256_set1_pd(pr.lo.z())),
        hix(_mm256_set1_pd(pr.hi.x())), hiy(_mm256_set1_pd(pr.hi.y())), hiz(_mm256_set1_pd(pr.hi.z())),
        r2(_mm256_set1_pd(pr.r * pr.r)), n_lo(_mm256_set1_pd(nl)), n_hi(_mm256_set1_pd(nh)) {}
  /// Lanes j..j+3: the probe meets the triangle's box and their extents along the sensor axis meet.
  [[gnu::target("avx2")]] __m256d meets(const KeptTriangles& kept, std::size_t j) const {
    const __m256d zero = _mm256_setzero_pd();
    const __m256d dx = _mm256_max_pd(zero, _mm256_max_pd(_mm256_sub_pd(_mm256_loadu_pd(kept.lo_x.data() + j), hix),
                                                         _mm256_sub_pd(lox, _mm256_loadu_pd(kept.hi_x.data() + j))));
    const __m256d dy = _mm256_max_pd(zero, _mm256_max_pd(_mm256_sub_pd(_mm256_loadu_pd(kept.lo_y.data() + j), hiy),
                                                         _mm256_sub_pd(loy, _mm256_loadu_pd(kept.hi_y.data() + j))));
    const __m256d dz = _mm256_max_pd(zero, _mm256_max_pd(_mm256_sub_pd(_mm256_loadu_pd(kept.lo_z.data() + j), hiz),
                                                         _mm256_sub_pd(loz, _mm256_loadu_pd(kept.hi_z.data() + j))));
    const __m256d d2 =
        _mm256_add_pd(_mm256_add_pd(_mm256_mul_pd(dx, dx), _mm256_mul_pd(dy, dy)), _mm256_mul_pd(dz, dz));
    return _mm256_and_pd(_mm256_cmp_pd(d2, r2, _CMP_LE_OQ),
                         _mm256_and_pd(_mm256_cmp_pd(n_hi, _mm256_loadu_pd(kept.n_lo.data() + j), _CMP_GE_OQ),
                                       _mm256_cmp_pd(n_lo, _mm256_loadu_pd(kept.n_hi.data() + j), _CMP_LE_OQ)));
  }
};

/// collectMeets<false> four triangles per instruction, for processors with AVX2 (chosen at run
/// time). `padded`: KeptTriangles::pad()'s size (the loop then has no tail), or kept.size().
[[gnu::target("avx2")]] std::size_t collectMeetsAvx2(const KeptTriangles& kept, std::size_t padded, const Probe& pr,
                                                     double n_lo, double n_hi, Index* hits) {
  const std::size_t m = kept.size();
  const ProbeLanes probe(pr, n_lo, n_hi);
  const Index* record = kept.record.data();
  std::size_t j = 0, n_hits = 0;
  for (; j + 4 <= padded; j += 4) {
    const int mask = _mm256_movemask_pd(probe.meets(kept, j));
    // Left-packed without a branch: the four slots are written, the count moves by the passes.
    const std::array<std::uint8_t, 4>& lanes = kLeftPack[mask];
    hits[n_hits] = record[j + lanes[0]];
    hits[n_hits + 1] = record[j + lanes[1]];
    hits[n_hits + 2] = record[j + lanes[2]];
    hits[n_hits + 3] = record[j + lanes[3]];
    n_hits += static_cast<std::size_t>(__builtin_popcount(static_cast<unsigned>(mask)));
  }
  // Leave the upper halves clean before the scalar tail and the return. GCC 12 inserts no
  // vzeroupper on the path through the tail's calls (meetsScalar is SSE code), so every function
  // after it ran with the AVX state dirty; on this machine that slowed the SSE code that followed,
  // ours and Bullet's (the exact stage, 0.38 ms a step on 8 tori × 2,000 vertices with the state
  // clean, 0.78 ms without).
  _mm256_zeroupper();
  for (; j < m; ++j) {
    hits[n_hits] = record[j];
    n_hits += static_cast<std::size_t>(meetsScalar(kept, j, pr, n_lo, n_hi));
  }
  return n_hits;
}

/// collectMeets<true> (self pairs) four triangles per instruction (AVX2): the same operations as
/// its SSE2 loop, so the same triangles pass, in the same order. `padded`: KeptTriangles::pad()'s
/// size (its boxes meet nothing, so no tail; the padding's rest centroids are never read as a pass).
[[gnu::target("avx2")]] std::size_t collectSelfMeetsAvx2(const KeptTriangles& kept, std::size_t padded,
                                                         const Probe& pr, double n_lo, double n_hi, const Vec3& rest,
                                                         double exclude2, Index* hits) {
  const ProbeLanes probe(pr, n_lo, n_hi);
  const double *gx = kept.mid_x.data(), *gy = kept.mid_y.data(), *gz = kept.mid_z.data();
  const Index* record = kept.record.data();
  const __m256d px = _mm256_set1_pd(rest.x()), py = _mm256_set1_pd(rest.y()), pz = _mm256_set1_pd(rest.z());
  const __m256d e2 = _mm256_set1_pd(exclude2);
  std::size_t n_hits = 0;
  for (std::size_t j = 0; j + 4 <= padded; j += 4) {
    const __m256d ex = _mm256_sub_pd(_mm256_loadu_pd(gx + j), px), ey = _mm256_sub_pd(_mm256_loadu_pd(gy + j), py);
    const __m256d ez = _mm256_sub_pd(_mm256_loadu_pd(gz + j), pz);
    const __m256d g2 =
        _mm256_add_pd(_mm256_add_pd(_mm256_mul_pd(ex, ex), _mm256_mul_pd(ey, ey)), _mm256_mul_pd(ez, ez));
    const __m256d ok = _mm256_and_pd(probe.meets(kept, j), _mm256_cmp_pd(g2, e2, _CMP_GE_OQ));
    // Most self pairs the boxes keep are neighbours at rest: passes are rare, so a branch.
    unsigned mask = static_cast<unsigned>(_mm256_movemask_pd(ok));
    while (mask != 0) {
      hits[n_hits++] = record[j + static_cast<std::size_t>(__builtin_ctz(mask))];
      mask &= mask - 1;
    }
  }
  _mm256_zeroupper();  // as in collectMeetsAvx2: the SSE code after it runs with a clean state
  return n_hits;
}
#endif

#if defined(PSC_HAVE_AVX2_PATH)
/// FilterDistance::of for four pairs at once (AVX2, chosen at run time): the same operations in the
/// same order, without fused multiply-adds, so the same bits.
struct FilterDistance4 {
  using V = __m256d;
  [[gnu::target("avx2")]] static V dot(V ax, V ay, V az, V bx, V by, V bz) {
    return _mm256_add_pd(_mm256_add_pd(_mm256_mul_pd(ax, bx), _mm256_mul_pd(ay, by)), _mm256_mul_pd(az, bz));
  }
  [[gnu::target("avx2")]] static V edge(V ex, V ey, V ez, V qx, V qy, V qz, V ee, V qe) {
    const V zero = _mm256_setzero_pd(), one = _mm256_set1_pd(1.0);
    // std::max(q, 0.0) and std::min(·, 1.0) pick the same values as maxpd(q, 0) and minpd(·, 1) for
    // every q that is not NaN (up to the sign of a zero); a NaN or infinite q (ee = 0) is blended away.
    const V clamped = _mm256_min_pd(_mm256_max_pd(_mm256_div_pd(qe, ee), zero), one);
    const V t = _mm256_blendv_pd(zero, clamped, _mm256_cmp_pd(ee, zero, _CMP_GT_OQ));
    const V x = _mm256_sub_pd(qx, _mm256_mul_pd(t, ex)), y = _mm256_sub_pd(qy, _mm256_mul_pd(t, ey));
    const V z = _mm256_sub_pd(qz, _mm256_mul_pd(t, ez));
    return dot(x, y, z, x, y, z);
  }
  [[gnu::target("avx2")]] static V lane(const Vec3* const v[4], int axis) {
    return _mm256_setr_pd((*v[0])[axis], (*v[1])[axis], (*v[2])[axis], (*v[3])[axis]);
  }
  /// Squared distances of points p[i] to triangles (a[i], b[i], c[i]), i < 4, into out.
  [[gnu::target("avx2")]] static void of(const Vec3* const p[4], const Vec3* const a[4], const Vec3* const b[4],
                                         const Vec3* const c[4], double out[4]) {
    const V px = lane(p, 0), py = lane(p, 1), pz = lane(p, 2);
    const V ax = lane(a, 0), ay = lane(a, 1), az = lane(a, 2);
    const V bx = lane(b, 0), by = lane(b, 1), bz = lane(b, 2);
    const V cx = lane(c, 0), cy = lane(c, 1), cz = lane(c, 2);
    const V abx = _mm256_sub_pd(bx, ax), aby = _mm256_sub_pd(by, ay), abz = _mm256_sub_pd(bz, az);
    const V acx = _mm256_sub_pd(cx, ax), acy = _mm256_sub_pd(cy, ay), acz = _mm256_sub_pd(cz, az);
    const V apx = _mm256_sub_pd(px, ax), apy = _mm256_sub_pd(py, ay), apz = _mm256_sub_pd(pz, az);
    const V bcx = _mm256_sub_pd(cx, bx), bcy = _mm256_sub_pd(cy, by), bcz = _mm256_sub_pd(cz, bz);
    const V bpx = _mm256_sub_pd(px, bx), bpy = _mm256_sub_pd(py, by), bpz = _mm256_sub_pd(pz, bz);
    const V d00 = dot(abx, aby, abz, abx, aby, abz), d11 = dot(acx, acy, acz, acx, acy, acz);
    const V d01 = dot(abx, aby, abz, acx, acy, acz);
    const V d20 = dot(apx, apy, apz, abx, aby, abz), d21 = dot(apx, apy, apz, acx, acy, acz);
    const V e22 = dot(bcx, bcy, bcz, bcx, bcy, bcz), e2p = dot(bpx, bpy, bpz, bcx, bcy, bcz);
    const V s = _mm256_min_pd(_mm256_min_pd(edge(abx, aby, abz, apx, apy, apz, d00, d20),
                                            edge(acx, acy, acz, apx, apy, apz, d11, d21)),
                              edge(bcx, bcy, bcz, bpx, bpy, bpz, e22, e2p));
    const V denom = _mm256_sub_pd(_mm256_mul_pd(d00, d11), _mm256_mul_pd(d01, d01));
    const V vn = _mm256_sub_pd(_mm256_mul_pd(d11, d20), _mm256_mul_pd(d01, d21));
    const V wn = _mm256_sub_pd(_mm256_mul_pd(d00, d21), _mm256_mul_pd(d01, d20));
    const V nx = _mm256_sub_pd(_mm256_mul_pd(aby, acz), _mm256_mul_pd(abz, acy));
    const V ny = _mm256_sub_pd(_mm256_mul_pd(abz, acx), _mm256_mul_pd(abx, acz));
    const V nz = _mm256_sub_pd(_mm256_mul_pd(abx, acy), _mm256_mul_pd(aby, acx));
    const V nn = dot(nx, ny, nz, nx, ny, nz), np = dot(nx, ny, nz, apx, apy, apz);
    const V zero = _mm256_setzero_pd();
    const V inside = _mm256_and_pd(
        _mm256_and_pd(_mm256_and_pd(_mm256_cmp_pd(denom, zero, _CMP_GT_OQ), _mm256_cmp_pd(nn, zero, _CMP_GT_OQ)),
                      _mm256_and_pd(_mm256_cmp_pd(vn, zero, _CMP_GE_OQ), _mm256_cmp_pd(wn, zero, _CMP_GE_OQ))),
        _mm256_cmp_pd(_mm256_add_pd(vn, wn), denom, _CMP_LE_OQ));
    // std::min(plane, s) is s < plane ? s : plane.
    const V plane = _mm256_div_pd(_mm256_mul_pd(np, np), nn);
    const V with_plane = _mm256_blendv_pd(plane, s, _mm256_cmp_pd(s, plane, _CMP_LT_OQ));
    _mm256_storeu_pd(out, _mm256_blendv_pd(s, with_plane, inside));
    _mm256_zeroupper();  // as in collectMeetsAvx2: the SSE code after it runs with a clean state
  }
};
#endif

/// MotionBound::Radius: of the pending pairs (in order), those whose vertex lies within its reach of
/// the triangle by the exact distance become candidates; a pair that is not within the vertex's
/// radius now is no candidate. Four pairs at a time with AVX2 where the processor has it.
void keepWithinReach(const PairContext& ctx, const VertexRec* recs) {
  Scratch& s = ctx.s;
  const std::size_t n = s.pending.size();
  std::size_t i = 0;
  // About half the pairs pass, so each is written and the count moves on when it does (a branch
  // would be mispredicted); the slots left over are cut off at the end.
  const std::size_t first = ctx.out.size();
  ctx.out.resize(first + n);
  std::uint64_t* out = ctx.out.data() + first;
  // With nearest_candidates each kept pair's distance goes beside it, the same way.
  std::vector<double>* dist = ctx.out_d2;
  if (dist != nullptr) dist->resize(first + n);
  double* out_d2 = dist != nullptr ? dist->data() + first : nullptr;
  if (ctx.out_k != nullptr) ctx.out_k->resize(first + n);
  Index* out_k = ctx.out_k != nullptr ? ctx.out_k->data() + first : nullptr;
  std::size_t kept = 0;
  std::size_t not_nearest = 0;
  const auto decide = [&](std::size_t at, double d2) {
    const VertexRec& vr = recs[s.pending[at].first];
    const TriangleCorners& tc = s.corners[s.pending[at].second];
    out[kept] = (std::uint64_t{vr.v} << 32) | tc.t;
    // Meeting pairs: a pair that came within the margins during the step is now no farther apart
    // than the margins plus the vertex's motion plus the motion of the triangle's point.
    bool keep = d2 < (ctx.meeting ? std::max(vr.reach2, reachOf(vr.x, ctx.margin_sum + vr.motion + tc.motion)) : vr.reach2);
    if (out_d2 != nullptr) {
      out_d2[kept] = d2;
      if (out_k != nullptr) out_k[kept] = s.corners[s.pending[at].second].k;
      // Within reach but outside the band of the vertex's nearest so far: the final pass would
      // drop it too (the least only falls).
      double& best = ctx.best2[vr.v];
      const bool near = d2 <= best * kNearestBand2;
      not_nearest += static_cast<std::size_t>(keep && !near);
      if (keep && d2 < best) best = d2;
      keep = keep && near;
    }
    kept += static_cast<std::size_t>(keep);
  };
#if defined(PSC_HAVE_AVX2_PATH)
  if (useAvx2Probes()) {
    // Four pairs a time; the tail one at a time (the same bits either way).
    for (; i + 4 <= n; i += 4) {
      const Vec3 *p[4], *a[4], *b[4], *c[4];
      for (int l = 0; l < 4; ++l) {
        const TriangleCorners& tc = s.corners[s.pending[i + l].second];
        p[l] = &recs[s.pending[i + l].first].x;
        a[l] = &tc.a;
        b[l] = &tc.b;
        c[l] = &tc.c;
      }
      alignas(32) double d2[4];
      FilterDistance4::of(p, a, b, c, d2);
      for (int l = 0; l < 4; ++l) decide(i + l, d2[l]);
    }
  }
#endif
  for (; i < n; ++i) {
    const TriangleCorners& tc = s.corners[s.pending[i].second];
    decide(i, FilterDistance::of(recs[s.pending[i].first].x, tc.a, tc.b, tc.c));
  }
  ctx.out.resize(first + kept);
  if (dist != nullptr) dist->resize(first + kept);
  if (ctx.out_k != nullptr) ctx.out_k->resize(first + kept);
  ctx.counters.candidates_beyond_reach += n - kept - not_nearest;
  ctx.counters.candidates_not_nearest += not_nearest;
  s.pending.clear();
}

/// The picking pass of chunkCandidates, one vertex at a time: of the `nv` vertices from `at` in
/// `lanes`, the indices (from 0) of those within their radius r of [lo_n, hi_n] along the sensor
/// axis (±infinity without sensors) and of the box `tbox`, into `picked`, in order; returns how
/// many, and adds to `dropped` those outside the slab. Starts at vertex `from`, after `n` picks.
std::size_t pickScalar(const VertexLanes& lanes, std::size_t at, std::size_t from, std::size_t nv, std::size_t n,
                       const MotionBox& tbox, double lo_n, double hi_n, Index* picked, std::size_t& dropped) {
  for (std::size_t i = from; i < nv; ++i) {
    const double x = lanes.x[at + i], y = lanes.y[at + i], z = lanes.z[at + i], r = lanes.r[at + i];
    const double xn = lanes.n[at + i];
    const bool in_slab = (xn + r >= lo_n) & (xn - r <= hi_n);
    const bool in_box = (x >= tbox.lo.x() - r) & (y >= tbox.lo.y() - r) & (z >= tbox.lo.z() - r) &
                        (x <= tbox.hi.x() + r) & (y <= tbox.hi.y() + r) & (z <= tbox.hi.z() + r);
    picked[n] = static_cast<Index>(i);
    n += static_cast<std::size_t>(in_slab & in_box);
    dropped += static_cast<std::size_t>(!in_slab);
  }
  return n;
}

/// The kept-triangle pass of chunkCandidates, one triangle at a time: of the `nt` triangles from
/// `at`, those whose box meets [lo, hi] and whose extent along the sensor axis meets [n_lo, n_hi],
/// into `kept` in order. Starts at triangle `from`.
void keepScalar(const TriangleLanes& t, std::size_t at, std::size_t from, std::size_t nt, const Vec3& lo,
                const Vec3& hi, double n_lo, double n_hi, bool self, KeptTriangles& kept) {
  for (std::size_t k = at + from; k < at + nt; ++k) {
    const bool meets = (t.lo_x[k] <= hi.x()) & (t.lo_y[k] <= hi.y()) & (t.lo_z[k] <= hi.z()) & (lo.x() <= t.hi_x[k]) &
                       (lo.y() <= t.hi_y[k]) & (lo.z() <= t.hi_z[k]) & (t.n_hi[k] >= n_lo) & (t.n_lo[k] <= n_hi);
    if (meets) kept.push(t, k, self);
  }
}

#if defined(PSC_HAVE_AVX2_PATH)
/// pickScalar four vertices per instruction (AVX2): the same comparisons of the same values, so
/// the same picks. The picked indices are stored without a branch: each lane writes its index and
/// the count moves on only when it passes.
[[gnu::target("avx2")]] std::size_t pickAvx2(const VertexLanes& lanes, std::size_t at, std::size_t nv,
                                             const MotionBox& tbox, double lo_n, double hi_n, Index* picked,
                                             std::size_t& dropped) {
  const double *px = lanes.x.data() + at, *py = lanes.y.data() + at, *pz = lanes.z.data() + at;
  const double *pr = lanes.r.data() + at, *pn = lanes.n.data() + at;
  const __m256d lx = _mm256_set1_pd(tbox.lo.x()), ly = _mm256_set1_pd(tbox.lo.y()), lz = _mm256_set1_pd(tbox.lo.z());
  const __m256d hx = _mm256_set1_pd(tbox.hi.x()), hy = _mm256_set1_pd(tbox.hi.y()), hz = _mm256_set1_pd(tbox.hi.z());
  const __m256d vlo = _mm256_set1_pd(lo_n), vhi = _mm256_set1_pd(hi_n);
  std::size_t i = 0, n = 0, out = 0;
  for (; i + 4 <= nv; i += 4) {
    const __m256d r = _mm256_loadu_pd(pr + i), xn = _mm256_loadu_pd(pn + i);
    const __m256d x = _mm256_loadu_pd(px + i), y = _mm256_loadu_pd(py + i), z = _mm256_loadu_pd(pz + i);
    const __m256d slab = _mm256_and_pd(_mm256_cmp_pd(_mm256_add_pd(xn, r), vlo, _CMP_GE_OQ),
                                       _mm256_cmp_pd(_mm256_sub_pd(xn, r), vhi, _CMP_LE_OQ));
    const __m256d low = _mm256_and_pd(_mm256_and_pd(_mm256_cmp_pd(x, _mm256_sub_pd(lx, r), _CMP_GE_OQ),
                                                    _mm256_cmp_pd(y, _mm256_sub_pd(ly, r), _CMP_GE_OQ)),
                                      _mm256_cmp_pd(z, _mm256_sub_pd(lz, r), _CMP_GE_OQ));
    const __m256d high = _mm256_and_pd(_mm256_and_pd(_mm256_cmp_pd(x, _mm256_add_pd(hx, r), _CMP_LE_OQ),
                                                     _mm256_cmp_pd(y, _mm256_add_pd(hy, r), _CMP_LE_OQ)),
                                       _mm256_cmp_pd(z, _mm256_add_pd(hz, r), _CMP_LE_OQ));
    const int in_slab = _mm256_movemask_pd(slab);
    const int m = _mm256_movemask_pd(_mm256_and_pd(slab, _mm256_and_pd(low, high)));
    out += static_cast<std::size_t>(4 - __builtin_popcount(static_cast<unsigned>(in_slab)));
    for (int l = 0; l < 4; ++l) {
      picked[n] = static_cast<Index>(i + static_cast<std::size_t>(l));
      n += static_cast<std::size_t>((m >> l) & 1);
    }
  }
  _mm256_zeroupper();  // as in collectMeetsAvx2: the SSE code after it runs with a clean state
  dropped += out;
  return pickScalar(lanes, at, i, nv, n, tbox, lo_n, hi_n, picked, dropped);
}

/// keepScalar four triangles per instruction (AVX2): the same comparisons of the same values, so
/// the same triangles in the same order.
[[gnu::target("avx2")]] void keepAvx2(const TriangleLanes& t, std::size_t at, std::size_t nt, const Vec3& lo,
                                      const Vec3& hi, double n_lo, double n_hi, bool self, KeptTriangles& kept) {
  const __m256d vlx = _mm256_set1_pd(lo.x()), vly = _mm256_set1_pd(lo.y()), vlz = _mm256_set1_pd(lo.z());
  const __m256d vhx = _mm256_set1_pd(hi.x()), vhy = _mm256_set1_pd(hi.y()), vhz = _mm256_set1_pd(hi.z());
  const __m256d vnl = _mm256_set1_pd(n_lo), vnh = _mm256_set1_pd(n_hi);
  std::size_t k = 0;
  for (; k + 4 <= nt; k += 4) {
    const std::size_t j = at + k;
    const __m256d a = _mm256_and_pd(
        _mm256_and_pd(_mm256_cmp_pd(_mm256_loadu_pd(t.lo_x.data() + j), vhx, _CMP_LE_OQ),
                      _mm256_cmp_pd(_mm256_loadu_pd(t.lo_y.data() + j), vhy, _CMP_LE_OQ)),
        _mm256_and_pd(_mm256_cmp_pd(_mm256_loadu_pd(t.lo_z.data() + j), vhz, _CMP_LE_OQ),
                      _mm256_cmp_pd(_mm256_loadu_pd(t.n_hi.data() + j), vnl, _CMP_GE_OQ)));
    const __m256d b = _mm256_and_pd(
        _mm256_and_pd(_mm256_cmp_pd(vlx, _mm256_loadu_pd(t.hi_x.data() + j), _CMP_LE_OQ),
                      _mm256_cmp_pd(vly, _mm256_loadu_pd(t.hi_y.data() + j), _CMP_LE_OQ)),
        _mm256_and_pd(_mm256_cmp_pd(vlz, _mm256_loadu_pd(t.hi_z.data() + j), _CMP_LE_OQ),
                      _mm256_cmp_pd(_mm256_loadu_pd(t.n_lo.data() + j), vnh, _CMP_LE_OQ)));
    unsigned m = static_cast<unsigned>(_mm256_movemask_pd(_mm256_and_pd(a, b)));
    while (m != 0) {
      const std::size_t l = static_cast<std::size_t>(__builtin_ctz(m));
      kept.push(t, j + l, self);
      m &= m - 1;
    }
  }
  _mm256_zeroupper();
  keepScalar(t, at, k, nt, lo, hi, n_lo, n_hi, self, kept);
}
#endif

/// Narrows the kept-triangle pass's box [lo, hi] and axis extent [n_lo, n_hi] to the union of what
/// the picked vertices' probes test: the box of each ball (x, r) and [xn − r, xn + r] along the
/// sensor axis. A triangle outside that union fails every probe, so none is lost. The axis bounds
/// are the probes' own values; the box grows by a relative 1e-9, so that a probe that passes by
/// rounding (a box distance of r up to an ulp) still finds its triangle kept. At least one pick.
void narrowToPicks(const VertexLanes& lanes, std::size_t at, const Index* picked, std::size_t n_picked, bool sensors,
                   Vec3& lo, Vec3& hi, double& n_lo, double& n_hi) {
  const double inf = std::numeric_limits<double>::infinity();
  double lx = inf, ly = inf, lz = inf, hx = -inf, hy = -inf, hz = -inf, nl = inf, nh = -inf, scale = 0.0;
  for (std::size_t k = 0; k < n_picked; ++k) {
    const std::size_t i = at + picked[k];
    const double x = lanes.x[i], y = lanes.y[i], z = lanes.z[i], r = lanes.r[i], xn = lanes.n[i];
    lx = std::min(lx, x - r);
    ly = std::min(ly, y - r);
    lz = std::min(lz, z - r);
    hx = std::max(hx, x + r);
    hy = std::max(hy, y + r);
    hz = std::max(hz, z + r);
    nl = std::min(nl, xn - r);
    nh = std::max(nh, xn + r);
    scale = std::max(scale, std::max({std::abs(x), std::abs(y), std::abs(z)}) + r);
  }
  const double slack = 1e-9 * scale;
  lo = lo.cwiseMax(Vec3(lx - slack, ly - slack, lz - slack));
  hi = hi.cwiseMin(Vec3(hx + slack, hy + slack, hz + slack));
  if (sensors) {
    n_lo = std::max(n_lo, nl);
    n_hi = std::min(n_hi, nh);
  }
}

bool restClears(double exclusion, double deviation, double reach, double rounding);
bool restClearsSquared(double exclusion, double deviation2, double reach, double rounding);

/// [beyond] The rest-shape bound for each picked vertex of a self pair, against the triangle chunk
/// ct of its own body. With R the rotation of ct's region and y = x − R·rest, every corner c of
/// ct's triangles has y_c in ct's y-box (RestFit::chunk_lo, chunk_hi), and for the point p of a
/// triangle t nearest to the vertex v now, y_p is an average of t's corners' y, so
///   |x_v − x_p| ≥ |rest_v − rest_p| − |y_v − y_p| ≥ dist_rest(v, t) − max_c |y_v − y_c|.
/// A pair the exclusion rule leaves in was at least E = self_rest_exclusion × R apart at rest: a
/// vertex whose y lies within E − reach of every corner of ct's y-box has no candidate in ct, and
/// leaves the picks. This is restApartChunks with the vertex's own y for the translation: the
/// vertex chunk's y-spread drops out, which clears vertices next to a bent chunk that the chunk
/// pair's bound cannot. Keeps the order of the remaining picks; returns how many.
std::size_t dropUnbentPicks(const PairContext& ctx, Index ct, const VertexRec* recs, Index* picked,
                            std::size_t n_picked) {
  const RestFit& f = *ctx.rest_fit;
  const Eigen::Matrix3d& rot = f.rot[ctx.tb.chunks.region_of[ct]];
  const Vec3& lo = f.chunk_lo[ct];
  const Vec3& hi = f.chunk_hi[ct];
  const double exclusion = std::sqrt(ctx.self_exclude2);
  // Every vertex's deviation is at least the box's half diagonal (its farthest corner from the
  // centre): when that alone leaves no room within the smallest reach, no pick can leave.
  double least_reach2 = std::numeric_limits<double>::infinity();
  for (std::size_t k = 0; k < n_picked; ++k) least_reach2 = std::min(least_reach2, recs[picked[k]].reach2);
  if (!restClearsSquared(exclusion, 0.25 * (hi - lo).squaredNorm(), std::sqrt(least_reach2), f.rounding)) return n_picked;
  std::size_t n = 0;
  for (std::size_t k = 0; k < n_picked; ++k) {
    const VertexRec& vr = recs[picked[k]];
    const Vec3 y = vr.x - rot * ctx.tb.rest[vr.v];
    const double deviation2 = (lo - y).cwiseAbs().cwiseMax((hi - y).cwiseAbs()).squaredNorm();
    picked[n] = picked[k];
    n += static_cast<std::size_t>(!restClearsSquared(exclusion, deviation2, std::sqrt(vr.reach2), f.rounding));
  }
  ctx.counters.self_vertices_unbent += n_picked - n;
  return n;
}

// Vertices of chunk cv (of ctx.vb) against the triangles owned by chunk ct (of ctx.tb).
void chunkCandidates(const PairContext& ctx, ChunkRef& cv, ChunkRef& ct) {
  const std::size_t nt = ctx.tb.chunks.triangleCount(ct.chunk);
  if (nt == 0) return;
  const bool sensors = ctx.axis.valid;
  const bool self = ctx.self_exclude2 >= 0.0;
  const MotionBox& tbox = ctx.tb.chunk_box[ct.chunk];
#if defined(PSC_HAVE_AVX2_PATH)
  const bool avx2 = useAvx2Probes();
#endif
  gatherVertices(ctx, cv);
  const std::size_t nv = ctx.vb.chunks.vertices(cv.chunk).size();
  Scratch& s = ctx.s;
  std::size_t probes = 0;
  // The vertices that can meet a triangle of ct: within r of its extent along the sensor axis (the
  // slab: a vertex farther than r from the triangle chunk's extent along n is farther than r from
  // each of its triangles) and of its box. Most fail, so they are picked without a branch each
  // (one per vertex would be mispredicted), then the picked ones are probed in order.
  if (s.picked.size() < nv) s.picked.resize(nv);
  std::size_t dropped = 0;
  const VertexRec* recs = s.verts.data() + cv.vertices_at;
  // Without sensors every vertex is in the slab: xn = 0 and r is finite (the refit checked).
  const double inf = std::numeric_limits<double>::infinity();
  const double slab_lo = sensors ? ct.lo_n : -inf, slab_hi = sensors ? ct.hi_n : inf;
  const auto at_v = static_cast<std::size_t>(cv.vertices_at);
  std::size_t n_picked;
#if defined(PSC_HAVE_AVX2_PATH)
  if (avx2)
    n_picked = pickAvx2(s.vert_lanes, at_v, nv, tbox, slab_lo, slab_hi, s.picked.data(), dropped);
  else
#endif
    n_picked = pickScalar(s.vert_lanes, at_v, 0, nv, 0, tbox, slab_lo, slab_hi, s.picked.data(), dropped);
  ctx.counters.vertices_dropped += dropped;
  if (n_picked == 0) return;
  if (ctx.rest_fit != nullptr) {
    n_picked = dropUnbentPicks(ctx, ct.chunk, recs, s.picked.data(), n_picked);
    if (n_picked == 0) return;
  }
  [[maybe_unused]] std::size_t padded = 0;  // the kept triangles, padded for collectMeetsAvx2
  // Only the triangles that reach the vertex chunk's grown box can meet any of its vertices.
  gatherTriangles(ctx, ct);
  {
    KeptTriangles& kept = s.kept;
    kept.reset(nt);
    const Grown& vbox = cv.box;
    const double g = ctx.triangle_share;
    // The vertex chunk's box and axis extent, brought to the triangles' side of the comparisons.
    Vec3 lo = vbox.lo.array() - g, hi = vbox.hi.array() + g;
    double n_lo = sensors ? cv.lo_n - vbox.g - g : -inf;
    double n_hi = sensors ? cv.hi_n + vbox.g + g : inf;
    // Narrowed to what the picked vertices' probes can reach: a chunk pair's picks lie where the
    // two chunks overlap, often a small part of the vertex chunk's box. (The probes test the balls
    // (x, r), except on the Ahead bound: the boxes of the paths ahead.)
    if (ctx.ahead_steps == 0.0) narrowToPicks(s.vert_lanes, at_v, s.picked.data(), n_picked, sensors, lo, hi, n_lo, n_hi);
    const auto at_t = static_cast<std::size_t>(ct.triangles_at);
#if defined(PSC_HAVE_AVX2_PATH)
    if (avx2)
      keepAvx2(s.tri_lanes, at_t, nt, lo, hi, n_lo, n_hi, self, kept);
    else
#endif
      keepScalar(s.tri_lanes, at_t, 0, nt, lo, hi, n_lo, n_hi, self, kept);
    if (kept.size() == 0) return;
    padded = kept.size();
#if defined(PSC_HAVE_AVX2_PATH)
    if (avx2) padded = kept.pad();
#endif
    if (s.hits.size() < nt + 3) s.hits.resize(nt + 3);  // collectMeetsAvx2 writes four slots at a time
  }
  // Self pairs: a triangle whose rest centroid lies within the exclusion distance of the vertex at
  // rest is excluded by the rule, and leaves the probes first; a relative 1e-9 below the rule's
  // square keeps the pairs at its edge for the rule itself (excludedSelfPair) to decide.
  const double prefilter2 = ctx.self_exclude2 * (1.0 - 1e-9);
  for (std::size_t pick = 0; pick < n_picked; ++pick) {
    const VertexRec& vr = recs[s.picked[pick]];
    const KeptTriangles& kept = s.kept;
    const std::size_t m = kept.size();
    probes += m;
    // The vertex's ball; with MotionBound::Ahead the box of its path ahead, grown by the margins
    // (the picking above and the distance below keep the ball (x, r), which holds every pair the
    // path ahead can keep that is within Bullet's radius).
    Probe pr{vr.x, vr.x, vr.r};
    if (ctx.best2 != nullptr && ctx.ahead_steps == 0.0) {
      // nearest_candidates: a triangle farther than the band of the vertex's nearest so far is no
      // candidate, and its box is no farther than it (the bound a little wider than the band, for
      // the rounding of the box distance against the exact one).
      pr.r = std::min(pr.r, nearestBand(ctx.best2[vr.v]));
    }
    double n_lo = sensors ? vr.xn - vr.r : -std::numeric_limits<double>::infinity();
    double n_hi = sensors ? vr.xn + vr.r : std::numeric_limits<double>::infinity();
    if (ctx.ahead_steps > 0.0 && !ctx.vb.previous.empty()) {
      // Where the path ahead ends: x + f·Δx, f = ahead_steps.
      const Vec3 ahead = vr.x + ctx.ahead_steps * (vr.x - ctx.vb.previous[vr.v]);
      pr = Probe{vr.x.cwiseMin(ahead), vr.x.cwiseMax(ahead), ctx.margin_sum};
      if (sensors) {
        const double an = ctx.axis.project(ahead);
        n_lo = std::min(vr.xn, an) - ctx.margin_sum;
        n_hi = std::max(vr.xn, an) + ctx.margin_sum;
      }
    }
    Index* hits = s.hits.data();
    std::size_t n_hits = 0;
#if defined(PSC_HAVE_AVX2_PATH)
    if (self && avx2)
      n_hits = collectSelfMeetsAvx2(kept, padded, pr, n_lo, n_hi, Vec3(ctx.tb.rest[vr.v] - ct.rest_origin),
                                    prefilter2, hits);
    else
#endif
    if (self)
      n_hits = collectMeets<true>(kept, pr, n_lo, n_hi, Vec3(ctx.tb.rest[vr.v] - ct.rest_origin), prefilter2,
                                  s.kept.meets.data(), hits);
#if defined(PSC_HAVE_AVX2_PATH)
    else if (avx2)
      n_hits = collectMeetsAvx2(kept, padded, pr, n_lo, n_hi, hits);
#endif
    else
      n_hits = collectMeets<false>(kept, pr, n_lo, n_hi, Vec3::Zero(), 0.0, s.kept.meets.data(), hits);
    for (std::size_t h = 0; h < n_hits; ++h) {
      const Index k = hits[h];
      const TriangleCorners& tc = s.corners[k];
      // Self pairs: the exclusion rule first, since most pairs of one body that the boxes keep are
      // neighbours at rest.
      if (ctx.self_exclude2 >= 0.0 && excludedSelfPair(ctx, vr.v, ctx.tb.chunks.triangle(ct.chunk, tc.k))) {
        ++ctx.counters.self_excluded_pairs;
        continue;
      }
      // With the radius bound the exact distance decides (below, for all of the chunk pair's
      // pairs at once); the swept bound keeps what the boxes keep: its pairs may meet during the step.
      if (ctx.swept)
        ctx.out.push_back((std::uint64_t{vr.v} << 32) | tc.t);
      else
        s.pending.emplace_back(s.picked[pick], k);
    }
  }
  ctx.counters.candidate_probes += probes;
  if (!s.pending.empty()) keepWithinReach(ctx, recs);
}

/// [beyond] The rest-shape bound of self-collision. A rigid motion T keeps distances, so for a
/// vertex v of chunk a and a triangle t of chunk b of one body,
///   dist_now(v, t) ≥ dist_rest(v, t) − dev_a(T) − dev_b(T),   dev_c(T) = max |x_u − T(rest_u)|
/// over c's vertex table, and a pair the exclusion rule leaves in was at least E =
/// self_rest_exclusion × R apart at rest. So when E − dev_a − dev_b reaches beyond every vertex's
/// reach, no pair of (a, b) can be a candidate: the surface there has not bent enough since rest
/// to touch itself. A flat cloth or a ball that keeps its shape costs what the refit's pass adds,
/// not its box tests. The refit leaves per chunk the y-box of y = x − R_r·rest (R_r its region's
/// rotation, RestFit in body.h); with T = R_a · + k_a, k_a the centre of a's y-box,
///   dev_a(T) ≤ h_a (the y-box's half diagonal),
///   dev_b(T) ≤ h_b + |k_b − k_a|                                  (b in a's region),
///   dev_b(T) ≤ h_b + ‖R_b − R_a‖_F ρ_b + |(R_b − R_a) q_b + k_b − k_a|  (otherwise; q_b, ρ_b the
///   rest sphere of b's table).
/// Regions are bounded the same way with their union y-boxes and rest spheres.
double restDeviation(const RestFit& f, Index ra, const Vec3& ka, double ha, Index rb, const Vec3& kb, double hb,
                     const Vec3& qb, double rho_b) {
  if (ra == rb) return ha + hb + (kb - ka).norm();
  const Eigen::Matrix3d d = f.rot[rb] - f.rot[ra];
  return ha + hb + d.norm() * rho_b + (d * qb + kb - ka).norm();
}

/// The bound clears `reach` (the largest reach of the vertices on either side). It is computed in
/// double from the same positions the distances are: a relative 1e-9 keeps its own rounding on
/// the safe side, and `rounding` (RestFit::rounding) that of y = x − R·rest, which is made at the
/// coordinates' magnitude (a body far from the origin) while the deviations are small.
bool restClears(double exclusion, double deviation, double reach, double rounding) {
  return exclusion - deviation >= reach * (1.0 + 1e-9) + rounding;
}

/// restClears of a squared deviation, without its square root.
bool restClearsSquared(double exclusion, double deviation2, double reach, double rounding) {
  const double room = exclusion - reach * (1.0 + 1e-9) - rounding;
  return room >= 0.0 && deviation2 <= room * room;
}

/// No (vertex of chunk a, triangle of chunk b) pair of X can be a candidate. Chunks of one region
/// share its rotation, and their y-boxes give the deviations exactly for any k: the distance from k
/// to each box's farthest corner. k is tried at the two centres and halfway between them.
bool restApartChunks(const Body& X, Index a, Index b, double exclusion, double reach) {
  const RestFit& f = *X.rest_fit;
  // No translation does better than the two half diagonals (each box's farthest corner is nearest
  // from its centre): most pairs of a body bent as a whole end here.
  if (!restClears(exclusion, f.chunk_half[a] + f.chunk_half[b], reach, f.rounding)) return false;
  const std::vector<Index>& region_of = X.chunks.region_of;
  double deviation = restDeviation(f, region_of[a], f.chunk_center[a], f.chunk_half[a], region_of[b],
                                   f.chunk_center[b], f.chunk_half[b], f.chunk_rest_center[b], f.chunk_rest_radius[b]);
  if (region_of[a] == region_of[b] && !restClears(exclusion, deviation, reach, f.rounding)) {
    const auto farthest = [&](Index c, const Vec3& k) {
      return (f.chunk_lo[c] - k).cwiseAbs().cwiseMax((f.chunk_hi[c] - k).cwiseAbs()).norm();
    };
    for (const Vec3& k : {f.chunk_center[a], f.chunk_center[b], Vec3(0.5 * (f.chunk_center[a] + f.chunk_center[b]))})
      deviation = std::min(deviation, farthest(a, k) + farthest(b, k));
  }
  return restClears(exclusion, deviation, reach, f.rounding);
}

/// No pair between regions i and j of X (both directions) can be a candidate.
bool restApartRegions(const Body& X, Index i, Index j, double exclusion, double reach) {
  const RestFit& f = *X.rest_fit;
  return restClears(exclusion,
                    restDeviation(f, i, f.region_center[i], f.region_half[i], j, f.region_center[j], f.region_half[j],
                                  f.region_rest_center[j], f.region_rest_radius[j]),
                    reach, f.rounding);
}

struct Group {
  BodyId vb, tb;
  std::vector<std::uint64_t> keys;
  std::vector<double> d2;  ///< CullParams::nearest: each key's squared distance
  std::vector<Index> k;    ///< CullParams::seeds: each key's owned-triangle index (PairContext::out_k)

  /// CullParams::nearest: keeps, in order, the keys within a relative 1e-4 of their vertex's least
  /// distance (kNearestBand2 on the squares). `least` is the table by vertex id that collected them
  /// (PairContext::best2: each vertex's least kept distance, +infinity for the others); it is all
  /// +infinity again on return. Returns how many went. With `seeds` (and `k` collected), each
  /// vertex's first kept key goes there as (vertex, owned-triangle index): NearestSeeds.
  std::size_t keepNearest(std::vector<double>& least, std::vector<std::pair<Index, Index>>* seeds = nullptr) {
    std::size_t out = 0;
    const bool with_k = seeds != nullptr && k.size() == keys.size();
    for (std::size_t i = 0; i < keys.size(); ++i)
      if (d2[i] <= least[keys[i] >> 32] * kNearestBand2) {
        if (with_k) k[out] = k[i];
        keys[out++] = keys[i];
      }
    // Each vertex met keeps its nearest key, so the kept keys reach every entry collection set.
    const double inf = std::numeric_limits<double>::infinity();
    for (std::size_t i = 0; i < out; ++i) {
      double& l = least[keys[i] >> 32];
      if (with_k && l != inf) seeds->emplace_back(static_cast<Index>(keys[i] >> 32), k[i]);
      l = inf;
    }
    const std::size_t gone = keys.size() - out;
    keys.resize(out);
    d2.clear();
    k = std::vector<Index>{};
    return gone;
  }
};

/// The regions of one body whose grown boxes meet a given box, without reading every region: the
/// boxes sorted by their low end along the body's longest axis, so a query reads only the regions
/// whose span along that axis can reach the box. Each body pair asks it of both bodies' regions
/// against the other's box; with one body of many regions (a soft floor of thousands under a
/// thousand small bodies) reading them all made that bodies × regions a step (a review's finding,
/// stop 47). Bodies of few regions are read in full, as before. The result is the same set, in
/// ascending region order, either way.
class RegionIndex {
 public:
  /// Below this many regions a body's regions are read in full.
  static constexpr Index kIndexedRegions = 64;

  RegionIndex(const Body& X, double motion_factor) {
    const Index n = static_cast<Index>(X.regionCount());
    boxes_.reserve(n);
    for (Index r = 0; r < n; ++r) boxes_.push_back(grown(X.region_box[r], X.margin, motion_factor));
    if (n < kIndexedRegions) return;
    axis_ = longestAxis(X.body_box.lo, X.body_box.hi);
    by_lo_.reserve(n);
    for (Index r = 0; r < n; ++r) {
      const Grown& g = boxes_[r];
      // A NaN or an empty box is kept out of the sort (it would break its order) and read in full.
      if (!(g.lo[axis_] <= g.hi[axis_])) {
        loose_.push_back(r);
        continue;
      }
      by_lo_.push_back({g.lo[axis_], r});
      longest_ = std::max(longest_, g.hi[axis_] - g.lo[axis_]);
    }
    std::sort(by_lo_.begin(), by_lo_.end());
    indexed_ = true;
  }

  const Grown& box(Index r) const { return boxes_[r]; }

  /// The regions whose grown box overlaps `other`, ascending, into `out` (cleared first).
  void overlapping(const Grown& other, std::vector<Index>& out) const {
    out.clear();
    if (!indexed_) {
      for (Index r = 0; r < static_cast<Index>(boxes_.size()); ++r)
        if (overlap(boxes_[r], other)) out.push_back(r);
      return;
    }
    // A region that meets `other` starts at most its own length before other.lo along the axis;
    // twice the longest length leaves room for the rounding of the lengths. The test itself is
    // the same overlap() as the full read's.
    const double from = other.lo[axis_] - 2.0 * longest_;
    auto it = std::lower_bound(by_lo_.begin(), by_lo_.end(), std::make_pair(from, Index(0)));
    if (!(from == from)) it = by_lo_.begin();  // a NaN query: read them all (none overlaps)
    for (; it != by_lo_.end() && !(it->first > other.hi[axis_]); ++it)
      if (overlap(boxes_[it->second], other)) out.push_back(it->second);
    for (const Index r : loose_)
      if (overlap(boxes_[r], other)) out.push_back(r);
    std::sort(out.begin(), out.end());
  }

 private:
  std::vector<Grown> boxes_;
  bool indexed_ = false;
  int axis_ = 0;
  double longest_ = 0.0;
  std::vector<std::pair<double, Index>> by_lo_;
  std::vector<Index> loose_;
};

class Collector {
 public:
  Collector(const CullParams& p, std::vector<FlaggedPair>& flagged, StepStats& c)
      : params_(p), flagged_(flagged), counters_(c) {}

  void bodyPair(const Body& A, const Body& B) {
    ++counters_.body_pairs;
    // The pair's motion bound: Ahead for the whole world, or for this pair (SensorWorld::setPairAhead).
    const bool pair_ahead = params_.ahead_steps == 0.0 && !params_.swept && params_.ahead_pairs != nullptr &&
                            std::binary_search(params_.ahead_pairs->begin(), params_.ahead_pairs->end(),
                                               std::make_pair(A.id, B.id));
    const double ahead_steps = pair_ahead ? params_.pair_ahead_steps : params_.ahead_steps;
    const Grown boxA = grown(A.body_box, A.margin, params_.motion_factor);
    const Grown boxB = grown(B.body_box, B.margin, params_.motion_factor);
    // Sweep along the longest axis of the two bodies' common box.
    const int ax = longestAxis(boxA.lo.cwiseMax(boxB.lo), boxA.hi.cwiseMin(boxB.hi));
    const auto regionItems = [&](const Body& X, const Grown& other, std::vector<SweepItem>& items) {
      items.clear();
      const RegionIndex& index = regionIndex(X);
      index.overlapping(other, region_hits_);
      for (const Index r : region_hits_) {
        const Grown& g = index.box(r);
        items.push_back({g.lo[ax], g.hi[ax], r});
      }
    };
    regionItems(A, boxB, s_.items_a);
    if (s_.items_a.empty()) return;
    regionItems(B, boxA, s_.items_b);
    Group ab{A.id, B.id, {}, {}, {}}, ba{B.id, A.id, {}, {}, {}};
    // NearestSeeds: only on the radius bound (Ahead's probes test the paths ahead instead).
    const bool seeded = params_.nearest && params_.seeds != nullptr && ahead_steps == 0.0;
    if (params_.nearest) {
      const double inf = std::numeric_limits<double>::infinity();
      if (least_.size() < A.chunks.vertexCount()) least_.resize(A.chunks.vertexCount(), inf);
      if (least_b_.size() < B.chunks.vertexCount()) least_b_.resize(B.chunks.vertexCount(), inf);
      if (seeded) {
        seedNearest(A, B, least_, seeded_a_);
        seedNearest(B, A, least_b_, seeded_b_);
      }
    }
    region_pairs_.clear();
    sweepBetween(s_.items_a, s_.items_b, [&](Index ri, Index rj) { region_pairs_.emplace_back(ri, rj); });
    // Bullet's contact solver is Gauss-Seidel: contacts in mesh order (not in sweep order) keep
    // its result independent of the sweep axis and measured better on resting stacks.
    std::sort(region_pairs_.begin(), region_pairs_.end());
    for (const auto& [ri, rj] : region_pairs_) regionPair(A, ri, B, rj, ab, ba, ahead_steps, seeded);
    if (params_.nearest) {
      record_.clear();
      counters_.candidates_not_nearest += ab.keepNearest(least_, seeded ? &record_ : nullptr);
      if (seeded) recordNearest(A, B);
      counters_.candidates_not_nearest += ba.keepNearest(least_b_, seeded ? &record_ : nullptr);
      if (seeded) recordNearest(B, A);
      // A seeded vertex left without candidates still holds its seed.
      for (const Index v : seeded_a_) least_[v] = std::numeric_limits<double>::infinity();
      for (const Index v : seeded_b_) least_b_[v] = std::numeric_limits<double>::infinity();
      seeded_a_.clear();
      seeded_b_.clear();
    }
    if (!ab.keys.empty()) groups.push_back(std::move(ab));
    if (!ba.keys.empty()) groups.push_back(std::move(ba));
  }

  std::vector<Group> groups;

  /// Self-collision of X: its region pairs (I ≤ J, I = J included) whose grown boxes overlap, by
  /// sort-and-sweep; in each, its chunk pairs likewise, and the (vertex, triangle) pairs of both
  /// directions that the boxes cannot rule out and the exclusion rule does not exclude. Every
  /// ordered (vertex chunk, triangle chunk) pair is visited once, so every pair comes out once.
  /// No sensor decision: the particles sense other bodies only.
  void selfBody(const Body& X) {
    const double mf = params_.motion_factor;
    // The self radius R stands for margin_A + margin_B: each side's boxes grow by R / 2.
    const double radius = selfContactRadius(X.margin, X.rest_mean_edge, params_.self_radius_edges);
    const double half = 0.5 * radius;
    // With the radius bound the motion term is the self one (psc::selfMotion), bounded per chunk
    // and region by the refit (RestFit); with the swept bound, the boxes hold the paths.
    static const RestFit kNone;
    const RestFit& fit = X.rest_fit ? *X.rest_fit : kNone;
    // With meeting pairs (params_.meeting) a body's pairs with itself keep the self rule's radius:
    // its exact stage decides at Bullet's radius, wider than the rule's, and would make contacts of
    // every pair the swept bound's boxes keep (a fast body: millions beyond the rule).
    const bool self_motion = fit.filled && !params_.swept;
    const auto regionBox = [&](Index r) {
      MotionBox box = X.region_box[r];
      if (self_motion) box.motion = fit.region_self_motion[r];
      return box;
    };
    const auto chunkBox = [&](Index c) {
      MotionBox box = X.chunk_box[c];
      if (self_motion) box.motion = fit.chunk_self_motion[c];
      return box;
    };
    std::vector<Grown>& boxes = self_boxes_;
    boxes.resize(X.regionCount());
    s_.items_a.clear();
    const int ax = longestAxis(X.body_box.lo, X.body_box.hi);
    region_pairs_.clear();
    for (Index r = 0; r < X.regionCount(); ++r) {
      boxes[r] = grown(regionBox(r), half, mf);
      s_.items_a.push_back({boxes[r].lo[ax], boxes[r].hi[ax], r});
      region_pairs_.emplace_back(r, r);
    }
    sweepWithin(s_.items_a, [&](Index a, Index b) {
      if (overlap(boxes[a], boxes[b])) region_pairs_.emplace_back(std::min(a, b), std::max(a, b));
    });
    std::sort(region_pairs_.begin(), region_pairs_.end());
    const double exclude = params_.self_rest_exclusion * radius;
    Group g{X.id, X.id, {}, {}, {}};
    const Axis no_axis;
    if (params_.nearest && least_.size() < X.chunks.vertexCount())
      least_.resize(X.chunks.vertexCount(), std::numeric_limits<double>::infinity());
    // The rest-shape bound needs the radius bound's reach (a swept pair may meet during the step).
    const bool rest_bound = params_.self_rest_bound && self_motion;
    PairContext ctx{X,         X,  radius, half, mf, params_.swept, no_axis, g.keys, counters_, s_, exclude * exclude,
                    self_motion ? &fit.mean_motion : nullptr, 0.0, params_.nearest ? &g.d2 : nullptr,
                    params_.nearest ? least_.data() : nullptr};
    if (rest_bound) ctx.rest_fit = &fit;
    const auto t0 = std::chrono::steady_clock::now();
    // The largest reach of the vertices in box b (reachOf of the largest radius and coordinate).
    const auto reachIn = [&](const MotionBox& b) {
      return (radius + motionTerm(mf, b.motion)) * (1.0 + 1e-5) + 1e-6 * std::max(b.lo.cwiseAbs().maxCoeff(), b.hi.cwiseAbs().maxCoeff());
    };
    for (const auto& [ri, rj] : region_pairs_) {
      ++counters_.self_region_pairs;
      if (rest_bound &&
          restApartRegions(X, ri, rj, exclude, std::max(reachIn(regionBox(ri)), reachIn(regionBox(rj))))) {
        ++counters_.self_region_pairs_unbent;
        continue;
      }
      const std::vector<double>* motion = self_motion ? &fit.chunk_self_motion : nullptr;
      nearChunks(X, ri, half, boxes[rj], no_axis, s_.near_a, motion);
      if (s_.near_a.empty()) continue;
      const bool same = ri == rj;
      if (!same) {
        nearChunks(X, rj, half, boxes[ri], no_axis, s_.near_b, motion);
        if (s_.near_b.empty()) continue;
      }
      std::vector<ChunkRef>& other = same ? s_.near_a : s_.near_b;
      const int cax = longestAxis(boxes[ri].lo.cwiseMax(boxes[rj].lo), boxes[ri].hi.cwiseMin(boxes[rj].hi));
      const auto itemsOf = [&](const std::vector<ChunkRef>& refs, std::vector<SweepItem>& items) {
        items.clear();
        for (std::size_t k = 0; k < refs.size(); ++k)
          items.push_back({refs[k].box.lo[cax], refs[k].box.hi[cax], static_cast<Index>(k)});
      };
      chunk_pairs_.clear();
      const auto keep = [&](Index ka, Index kb) {
        if (overlap(s_.near_a[ka].box, other[kb].box)) chunk_pairs_.emplace_back(ka, kb);
      };
      itemsOf(s_.near_a, s_.items_a);
      if (same) {
        for (std::size_t k = 0; k < s_.near_a.size(); ++k) chunk_pairs_.emplace_back(k, k);
        sweepWithin(s_.items_a, [&](Index a, Index b) { keep(std::min(a, b), std::max(a, b)); });
      } else {
        itemsOf(s_.near_b, s_.items_b);
        sweepBetween(s_.items_a, s_.items_b, keep);
      }
      // No sort: the body's keys are sorted below, and what they are does not depend on the order.
      counters_.chunk_pairs += chunk_pairs_.size();
      s_.clearRecords();
      for (const auto& [ka, kb] : chunk_pairs_) {
        ChunkRef& ca = s_.near_a[ka];
        ChunkRef& cb = other[kb];
        const auto collect = [&](ChunkRef& cv, ChunkRef& ct) {
          if (rest_bound && restApartChunks(X, cv.chunk, ct.chunk, exclude, reachIn(chunkBox(cv.chunk)))) {
            ++counters_.self_chunk_pairs_unbent;
            return;
          }
          chunkCandidates(ctx, cv, ct);
        };
        collect(ca, cb);
        if (&ca != &cb) collect(cb, ca);
      }
    }
    if (params_.nearest) counters_.candidates_not_nearest += g.keepNearest(least_);
    counters_.ms_candidates += std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
    if (!g.keys.empty()) {
      std::sort(g.keys.begin(), g.keys.end());
      groups.push_back(std::move(g));
    }
  }

  /// NearestSeeds: this step's seeds become the last step's (call once, after the body pairs).
  void finishSeeds() {
    NearestSeeds& n = *params_.seeds;
    n.pairs.swap(n.next);
    n.next.clear();
    std::sort(n.pairs.begin(), n.pairs.end(), [](const NearestSeeds::Pair& x, const NearestSeeds::Pair& y) {
      return x.vb != y.vb ? x.vb < y.vb : x.tb < y.tb;
    });
  }

 private:
  /// Group::keepNearest's tables by vertex id, for the two directions of a body pair
  /// (PairContext::best2 while collecting; +infinity between body pairs).
  std::vector<double> least_, least_b_;
  /// NearestSeeds: the vertices whose least (least_, least_b_) holds a seed, and the seeds one
  /// direction of a body pair records for the next step.
  std::vector<Index> seeded_a_, seeded_b_;
  std::vector<std::pair<Index, Index>> record_;

  /// Starts the nearest search of V's vertices against T from the last step's nearest triangles:
  /// least[v] becomes the squared distance to them now, in the very arithmetic of the candidate
  /// filter (the same corners in the same order, filterDistance2x4), rounded up by a relative
  /// 1e-12. The triangle is T's, so the vertex's nearest candidate is at most that far: every
  /// candidate past the band of the seed would be dropped by keepNearest anyway, and the seed's own
  /// triangle, if within reach, is found again (its box is within the seed's distance), so
  /// keepNearest's least is the one it would be without the seed.
  void seedNearest(const Body& V, const Body& T, std::vector<double>& least, std::vector<Index>& seeded) {
    const NearestSeeds::Pair* p = params_.seeds->find(V.id, T.id);
    if (p == nullptr || p->v_partition != V.partition_number || p->t_partition != T.partition_number) return;
    const ChunkLists& ch = T.chunks;
    const Index owned = ch.triangle_begin.back();
    Vec3 at[4][4];
    const Vec3 *pp[4], *pa[4], *pb[4], *pc[4];
    for (int l = 0; l < 4; ++l) pp[l] = &at[l][0], pa[l] = &at[l][1], pb[l] = &at[l][2], pc[l] = &at[l][3];
    Index vs[4];
    int n = 0;
    const auto flush = [&] {
      for (int l = n; l < 4; ++l)
        for (int c = 0; c < 4; ++c) at[l][c] = at[0][c];
      alignas(32) double d2[4];
      filterDistance2x4(pp, pa, pb, pc, d2);
      for (int l = 0; l < n; ++l) {
        const double bound = d2[l] * (1.0 + 1e-12);
        double& best = least[vs[l]];
        if (!(bound < best)) continue;
        if (best == std::numeric_limits<double>::infinity()) seeded.push_back(vs[l]);
        best = bound;
      }
      n = 0;
    };
    for (const auto& [v, k] : p->seeds) {
      if (v >= V.vertex_count || k >= owned) continue;  // cannot happen within one partition
      const Index c = static_cast<Index>(std::upper_bound(ch.triangle_begin.begin(), ch.triangle_begin.end(), k) -
                                         ch.triangle_begin.begin()) - 1;
      const Triangle tri = ch.triangle(c, k);
      at[n][0] = V.positions[v];
      for (int j = 0; j < 3; ++j) at[n][j + 1] = T.positions[tri[static_cast<std::size_t>(j)]];
      vs[n] = v;
      if (++n == 4) flush();
    }
    if (n > 0) flush();
    counters_.nearest_seeded += seeded.size();
  }

  /// record_ (the first kept key of each vertex of V against T) becomes the next step's seeds, in
  /// the memory of the pair's last list (its seeding is done), so that a steady contact allocates
  /// nothing; a list that shrank to under half its memory gets a new one of its size.
  void recordNearest(const Body& V, const Body& T) {
    if (!record_.empty()) {
      NearestSeeds::Pair p;
      p.vb = V.id;
      p.tb = T.id;
      p.v_partition = V.partition_number;
      p.t_partition = T.partition_number;
      if (NearestSeeds::Pair* last = params_.seeds->find(V.id, T.id)) p.seeds = std::move(last->seeds);
      if (p.seeds.capacity() > 2 * record_.size()) p.seeds = std::vector<std::pair<Index, Index>>{};
      p.seeds.assign(record_.begin(), record_.end());
      params_.seeds->next.push_back(std::move(p));
    }
    record_.clear();
  }

  /// `ahead_steps`: the body pair's PairContext::ahead_steps (0: not on the Ahead bound).
  /// `seeded`: record each candidate's owned-triangle index (NearestSeeds).
  void regionPair(const Body& A, Index ri, const Body& B, Index rj, Group& ab, Group& ba, double ahead_steps,
                  bool seeded) {
    const double mf = params_.motion_factor;
    const Grown boxI = grown(A.region_box[ri], A.margin, mf);
    const Grown boxJ = grown(B.region_box[rj], B.margin, mf);
    if (!overlap(boxI, boxJ)) return;
    ++counters_.region_pairs;
    Axis axis;
    if (params_.use_sensors) {
      // The sensors' axis: from the particle of region I to the particle of region J.
      const Vec3 d = B.positions[B.particle_vertex[rj]] - A.positions[A.particle_vertex[ri]];
      const double len = d.norm();
      const double scale = (boxI.hi - boxI.lo).norm() + (boxJ.hi - boxJ.lo).norm();
      if (len > 1e-9 * scale && std::isfinite(len)) {
        axis.valid = true;
        axis.n = d / len;
        axis.abs_n = axis.n.cwiseAbs();
      }
    }
    // Only the chunks of I that reach J's box and of J that reach I's box can pair up.
    nearChunks(A, ri, A.margin, boxJ, axis, s_.near_a);
    if (s_.near_a.empty()) return;
    nearChunks(B, rj, B.margin, boxI, axis, s_.near_b);
    if (s_.near_b.empty()) return;
    if (axis.valid && !sensorSlab()) {
      ++counters_.region_pairs_separated;
      return;
    }
    FlaggedPair f;
    f.body_a = A.id;  // bodies come ordered by id
    f.region_a = ri;
    f.body_b = B.id;
    f.region_b = rj;
    f.by_bounds = true;
    flagged_.push_back(f);

    const auto t0 = std::chrono::steady_clock::now();
    PairContext to_b{A, B, A.margin + B.margin, B.margin, mf, params_.swept, axis, ab.keys, counters_, s_,
                     -1.0, nullptr, ahead_steps, params_.nearest ? &ab.d2 : nullptr,
                     params_.nearest ? least_.data() : nullptr, seeded ? &ab.k : nullptr};
    PairContext to_a{B, A, A.margin + B.margin, A.margin, mf, params_.swept, axis, ba.keys, counters_, s_,
                     -1.0, nullptr, ahead_steps, params_.nearest ? &ba.d2 : nullptr,
                     params_.nearest ? least_b_.data() : nullptr, seeded ? &ba.k : nullptr};
    to_b.meeting = to_a.meeting = params_.meeting && ahead_steps == 0.0;
    const int ax = longestAxis(boxI.lo.cwiseMax(boxJ.lo), boxI.hi.cwiseMin(boxJ.hi));
    s_.items_a.clear();
    s_.items_b.clear();
    for (std::size_t k = 0; k < s_.near_a.size(); ++k)
      s_.items_a.push_back({s_.near_a[k].box.lo[ax], s_.near_a[k].box.hi[ax], static_cast<Index>(k)});
    for (std::size_t k = 0; k < s_.near_b.size(); ++k)
      s_.items_b.push_back({s_.near_b[k].box.lo[ax], s_.near_b[k].box.hi[ax], static_cast<Index>(k)});
    chunk_pairs_.clear();
    sweepBetween(s_.items_a, s_.items_b, [&](Index ka, Index kb) {
      const ChunkRef& ca = s_.near_a[ka];
      const ChunkRef& cb = s_.near_b[kb];
      if (!overlap(ca.box, cb.box)) return;
      if (axis.valid && (ca.hi_n + ca.box.g + cb.box.g < cb.lo_n || cb.hi_n + ca.box.g + cb.box.g < ca.lo_n)) return;
      chunk_pairs_.emplace_back(ka, kb);
    });
    std::sort(chunk_pairs_.begin(), chunk_pairs_.end());  // mesh order, as for region pairs
    counters_.chunk_pairs += chunk_pairs_.size();
    s_.clearRecords();
    // Each chunk is gathered once as a vertex side for one direction and as a triangle side for
    // the other: two passes keep the two directions' records apart.
    const double margin_sum = A.margin + B.margin;
    BallBoxes& balls_a = ballsOf(A);
    BallBoxes& balls_b = ballsOf(B);
    for (const auto& [ka, kb] : chunk_pairs_)
      if (verticesReach(A, balls_a, s_.near_a[ka].chunk, B, s_.near_b[kb].chunk, margin_sum))
        chunkCandidates(to_b, s_.near_a[ka], s_.near_b[kb]);
    for (ChunkRef& c : s_.near_a) c.vertices_at = c.triangles_at = -1;
    for (ChunkRef& c : s_.near_b) c.vertices_at = c.triangles_at = -1;
    s_.clearRecords();
    for (const auto& [ka, kb] : chunk_pairs_)
      if (verticesReach(B, balls_b, s_.near_b[kb].chunk, A, s_.near_a[ka].chunk, margin_sum))
        chunkCandidates(to_a, s_.near_b[kb], s_.near_a[ka]);
    counters_.ms_candidates += std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
  }

  /// Per body met this step, per chunk: the box of its own vertices' motion balls (x ± motion_factor
  /// × |Δx|), made on first use (most chunks are never near another body); empty for a body whose
  /// refit kept its own-vertex boxes (Body::chunk_own), which verticesReach takes instead.
  struct BallBoxes {
    std::vector<char> made;
    std::vector<Vec3> lo, hi;
  };
  std::unordered_map<BodyId, BallBoxes> balls_;  ///< by body id (references stay valid)

  BallBoxes& ballsOf(const Body& V) {
    BallBoxes& b = balls_[V.id];
    if (b.made.empty() && V.chunk_own.empty()) {  // with own boxes verticesReach needs no table
      b.made.assign(V.chunk_box.size(), 0);
      b.lo.resize(V.chunk_box.size());
      b.hi.resize(V.chunk_box.size());
    }
    return b;
  }

  /// Whether any own vertex of V's chunk cv can pick a triangle of T's chunk ct: chunkCandidates
  /// picks a vertex whose ball (x, margin_sum + motion_factor·|Δx|) meets ct's box, and every such
  /// ball lies in cv's ball box grown by margin_sum (rounded up). In most chunk pairs whose boxes
  /// meet, one direction or both have no such vertex (a chunk's box also holds the corners its
  /// triangles borrow from its neighbours), and that direction's vertices need not be gathered.
  /// The swept bound gathers other balls (about the paths' midpoints): always true there.
  /// `balls`: V's table (ballsOf).
  bool verticesReach(const Body& V, BallBoxes& balls, Index cv, const Body& T, Index ct, double margin_sum) {
    if (params_.swept) return true;
    // Meeting pairs: a vertex's probes reach at least its own path (gatherVertices).
    const double factor = params_.meeting ? std::max(params_.motion_factor, 1.0) : params_.motion_factor;
    Vec3 lo, hi;
    if (!V.chunk_own.empty()) {
      // The refit's box of the chunk's own vertices, grown by factor × the chunk's largest own
      // motion (chunk_box's, never below any vertex's |Δx|), holds every ball without reading a
      // vertex (the table below reads each, from Bullet's nodes a cache miss apiece on a large
      // body). Rounding is monotonic, so it also holds the table's rounded balls.
      const OwnBox& own = V.chunk_own[cv];
      const double m = motionTerm(factor, V.chunk_box[cv].motion);
      lo = Vec3(double(own.lo[0]) - m, double(own.lo[1]) - m, double(own.lo[2]) - m);
      hi = Vec3(double(own.hi[0]) + m, double(own.hi[1]) + m, double(own.hi[2]) + m);
    } else {
      if (!balls.made[cv]) {
        Vec3 l = Vec3::Constant(std::numeric_limits<double>::infinity()), h = -l;
        const bool moved = !V.previous.empty();
        for (const Index v : V.chunks.vertices(cv)) {
          const Vec3 x = V.positions[v];
          const double m = moved ? factor * (x - V.previous[v]).norm() : 0.0;
          l = l.cwiseMin(Vec3(x.array() - m));
          h = h.cwiseMax(Vec3(x.array() + m));
        }
        balls.lo[cv] = l;
        balls.hi[cv] = h;
        balls.made[cv] = 1;
      }
      lo = balls.lo[cv];
      hi = balls.hi[cv];
    }
    if (!(lo.array() <= hi.array()).all()) return false;  // no own vertex
    const double g = margin_sum * (1.0 + 1e-9) + 1e-9 * std::max(lo.cwiseAbs().maxCoeff(), hi.cwiseAbs().maxCoeff());
    const MotionBox& t = T.chunk_box[ct];
    return ((lo.array() - g) <= t.hi.array()).all() && (t.lo.array() <= (hi.array() + g)).all();
  }

  /// Region r's chunks of X whose boxes, grown by `margin` and the motion term, meet `other`, with
  /// their extents along `axis`. `motion`: per chunk, the motion term's length to grow by instead of
  /// chunk_box[c].motion.
  void nearChunks(const Body& X, Index r, double margin, const Grown& other, const Axis& axis,
                  std::vector<ChunkRef>& out, const std::vector<double>* motion = nullptr) {
    out.clear();
    for (Index c = X.chunks.region_begin[r]; c < X.chunks.region_begin[r + 1]; ++c) {
      MotionBox box = X.chunk_box[c];
      if (motion != nullptr) box.motion = (*motion)[c];
      const Grown g = grown(box, margin, params_.motion_factor);
      if (!overlap(g, other)) continue;
      ChunkRef ref{c, 0.0, 0.0, g};
      if (axis.valid) axis.extent(X.chunk_box[c], ref.lo_n, ref.hi_n);
      out.push_back(ref);
    }
    counters_.chunks_in += out.size();
  }

  /// The sensor decision along the axis n (from I's particle towards J's): the highest reach of
  /// I's chunks and the lowest of J's. When I's highest stays below J's lowest the pair is apart
  /// (false); otherwise the chunks that cannot reach across are dropped and the pair goes on.
  bool sensorSlab() {
    std::vector<ChunkRef>& a = s_.near_a;
    std::vector<ChunkRef>& b = s_.near_b;
    for (int pass = 0; pass < 2; ++pass) {
      double hi_a = -std::numeric_limits<double>::infinity(), lo_b = std::numeric_limits<double>::infinity();
      for (const ChunkRef& c : a) hi_a = std::max(hi_a, c.hi_n + c.box.g);
      for (const ChunkRef& c : b) lo_b = std::min(lo_b, c.lo_n - c.box.g);
      if (hi_a < lo_b) return false;
      // A chunk of I can only meet J if its grown top reaches J's lowest grown point; likewise
      // a chunk of J must reach down to I's highest.
      const std::size_t na = a.size(), nb = b.size();
      a.erase(std::remove_if(a.begin(), a.end(), [&](const ChunkRef& c) { return c.hi_n + c.box.g < lo_b; }), a.end());
      b.erase(std::remove_if(b.begin(), b.end(), [&](const ChunkRef& c) { return c.lo_n - c.box.g > hi_a; }), b.end());
      counters_.chunks_dropped += (na - a.size()) + (nb - b.size());
      if (a.empty() || b.empty()) return false;
      if (a.size() == na && b.size() == nb) break;
    }
    return true;
  }

  const CullParams& params_;
  std::vector<FlaggedPair>& flagged_;
  StepStats& counters_;
  Scratch s_;
  std::vector<std::pair<Index, Index>> region_pairs_, chunk_pairs_;
  std::vector<Grown> self_boxes_;
  /// Each body's region boxes, made at its first pair of the step.
  const RegionIndex& regionIndex(const Body& X) {
    auto it = region_index_.find(X.id);
    if (it == region_index_.end()) it = region_index_.emplace(X.id, RegionIndex(X, params_.motion_factor)).first;
    return it->second;
  }
  std::unordered_map<BodyId, RegionIndex> region_index_;
  std::vector<Index> region_hits_;
};

}  // namespace

std::vector<std::pair<Index, Index>> overlappingBodies(const std::vector<Body*>& bodies, const CullParams& params) {
  // Sort and sweep along the axis where the bodies' centres spread most.
  Vec3 lo = Vec3::Constant(std::numeric_limits<double>::infinity()), hi = -lo;
  for (const Body* b : bodies) {
    const Vec3 c = 0.5 * (b->body_box.lo + b->body_box.hi);
    lo = lo.cwiseMin(c);
    hi = hi.cwiseMax(c);
  }
  const int ax = bodies.empty() ? 0 : longestAxis(lo, hi);
  std::vector<SweepItem> items;
  std::vector<Grown> boxes(bodies.size());
  for (std::size_t i = 0; i < bodies.size(); ++i) {
    boxes[i] = grown(bodies[i]->body_box, bodies[i]->margin, params.motion_factor);
    items.push_back({boxes[i].lo[ax], boxes[i].hi[ax], static_cast<Index>(i)});
  }
  sortItems(items);
  std::vector<std::pair<Index, Index>> pairs;
  for (std::size_t i = 0; i < items.size(); ++i)
    for (std::size_t k = i + 1; k < items.size() && items[k].lo <= items[i].hi; ++k) {
      const Index x = items[i].id, y = items[k].id;
      if (overlap(boxes[x], boxes[y])) pairs.emplace_back(std::min(x, y), std::max(x, y));
    }
  std::sort(pairs.begin(), pairs.end());  // the result does not depend on the sweep axis
  return pairs;
}

std::vector<std::vector<char>> regionsNearOtherBodies(const std::vector<Body*>& bodies, const BodyPairs& pairs,
                                                      const CullParams& params) {
  std::vector<std::vector<char>> near(bodies.size());
  for (std::size_t i = 0; i < bodies.size(); ++i) near[i].assign(bodies[i]->regionCount(), 0);
  // Each body's region boxes, made at its first pair (RegionIndex: not every region per pair).
  std::vector<std::optional<RegionIndex>> index(bodies.size());
  std::vector<Index> hits;
  for (const auto& [i, j] : pairs)
    for (const auto& [x, y] : {std::pair<Index, Index>{i, j}, std::pair<Index, Index>{j, i}}) {
      if (!index[x]) index[x].emplace(*bodies[x], params.motion_factor);
      const Grown other = grown(bodies[y]->body_box, bodies[y]->margin, params.motion_factor);
      index[x]->overlapping(other, hits);
      for (const Index r : hits) near[x][r] = 1;
    }
  return near;
}

bool avx2ProbesAvailable() {
#if defined(PSC_HAVE_AVX2_PATH)
  static const bool has = __builtin_cpu_supports("avx2") != 0;
  return has;
#else
  return false;
#endif
}

void allowAvx2Probes(bool allowed) { g_avx2_allowed.store(allowed, std::memory_order_relaxed); }

NearestSeeds::Pair* NearestSeeds::find(BodyId vb, BodyId tb) {
  const auto it = std::lower_bound(pairs.begin(), pairs.end(), std::make_pair(vb, tb), [](const Pair& p, const auto& key) {
    return p.vb != key.first ? p.vb < key.first : p.tb < key.second;
  });
  return it != pairs.end() && it->vb == vb && it->tb == tb ? &*it : nullptr;
}

double filterDistance2(const Vec3& p, const Vec3& a, const Vec3& b, const Vec3& c) {
  return FilterDistance::of(p, a, b, c);
}

void filterDistance2x4(const Vec3* const p[4], const Vec3* const a[4], const Vec3* const b[4], const Vec3* const c[4],
                       double out[4]) {
#if defined(PSC_HAVE_AVX2_PATH)
  if (useAvx2Probes()) {
    FilterDistance4::of(p, a, b, c, out);
    return;
  }
#endif
  for (int l = 0; l < 4; ++l) out[l] = FilterDistance::of(*p[l], *a[l], *b[l], *c[l]);
}

void cullAndCollect(const std::vector<Body*>& bodies, const BodyPairs& pairs, const CullParams& params,
                    std::vector<FlaggedPair>& flagged, std::vector<CandidatePair>& candidates, StepStats& counters) {
  Collector collect(params, flagged, counters);
  for (const auto& [i, j] : pairs) collect.bodyPair(*bodies[i], *bodies[j]);
  if (params.nearest && params.seeds != nullptr) collect.finishSeeds();
  for (const Body* b : bodies)
    if (b->selfCollides()) collect.selfBody(*b);

  std::vector<Group>& groups = collect.groups;
  std::sort(groups.begin(), groups.end(),
            [](const Group& x, const Group& y) { return x.vb != y.vb ? x.vb < y.vb : x.tb < y.tb; });
  std::size_t total = candidates.size();
  for (const Group& g : groups) total += g.keys.size();
  if (total > candidates.capacity()) {
    // An empty list's old block is freed before the new one is taken (a reserve holds both at
    // once). Room for an eighth more and for twice the growth since the last step, so that a list
    // growing from step to step is not taken anew every step (a new block costs the allocator's
    // system calls, which took milliseconds at times on a virtual machine: docs/DECISIONS.md,
    // "Stop 42", the plugin's contact arrays), while a list that has stopped growing keeps an eighth.
    const std::size_t growth = total > params.last_candidates ? total - params.last_candidates : 0;
    if (candidates.empty()) candidates = std::vector<CandidatePair>();
    candidates.reserve(total + total / 8 + 2 * growth);
  }
  // Each group's keys are freed once copied: held to the end, they were 22 MB of the peak of a
  // settled fine pile (8 tori × 8,000 vertices, 1.9 million candidates a step) beside the list.
  for (Group& g : groups) {
    for (std::uint64_t k : g.keys)
      candidates.push_back({g.vb, static_cast<Index>(k >> 32), g.tb, static_cast<Index>(k & 0xFFFFFFFFu)});
    std::vector<std::uint64_t>().swap(g.keys);
  }
}

}  // namespace psc::detail
