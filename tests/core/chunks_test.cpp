// The chunk lists under the regions (src/body.h): each vertex's foreign chunks, the chunks other
// than its own whose owned triangles hold it, kept in two slots and a list of the rare rest.
#include "../../src/body.h"
#include "../../src/bounds.h"

#include "psc/mesh.h"
#include "psc/shapes.h"

#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <limits>
#include <iostream>
#include <random>
#include <set>
#include <utility>
#include <vector>

namespace psc::detail {
namespace {

std::vector<Index> foreignOf(const ForeignChunks& f, Index v) {
  std::vector<Index> out;
  f.forEach(v, [&](Index c) { out.push_back(c); });
  return out;
}

// Seeded random (vertex, chunk) pairs, duplicates included, with up to six chunks per vertex and
// chunk counts that need one, two and four bytes a slot: the slots and the rest give each vertex
// its chunks ascending and once, like IndexRows::fromPairs.
TEST(ForeignChunks, EqualTheRowsOfThePairsForEverySlotWidth) {
  std::mt19937 rng(7);
  for (const Index chunks : {Index{200}, Index{1000}, Index{70000}}) {
    const std::size_t vertices = 3000;
    std::vector<std::pair<Index, Index>> pairs;
    std::uniform_int_distribution<Index> chunk(0, chunks - 1);
    std::uniform_int_distribution<int> count(0, 6);
    for (Index v = 0; v < vertices; ++v) {
      const int k = count(rng);
      for (int i = 0; i < k; ++i) {
        pairs.emplace_back(v, chunk(rng));
        if (i == 0 && v % 7 == 0) pairs.push_back(pairs.back());  // a duplicate
      }
    }
    std::shuffle(pairs.begin(), pairs.end(), rng);
    const ForeignChunks f(vertices, chunks, pairs);
    const IndexRows rows = IndexRows::fromPairs(vertices, pairs);
    EXPECT_EQ(f.none(), chunks);
    EXPECT_EQ(f.slotWidth(), chunks < 256 ? 1u : chunks < 65536 ? 2u : 4u);
    std::size_t extra = 0, with_three = 0;
    for (Index v = 0; v < vertices; ++v) {
      const IndexRange row = rows.row(v);
      const std::vector<Index> expected(row.begin(), row.end());
      ASSERT_EQ(foreignOf(f, v), expected) << "vertex " << v << " of " << chunks << " chunks";
      EXPECT_EQ(f.first(v), expected.size() > 0 ? expected[0] : chunks);
      EXPECT_EQ(f.second(v), expected.size() > 1 ? expected[1] : chunks);
      extra += expected.size() > 2 ? expected.size() - 2 : 0;
      with_three += expected.size() > 2;
    }
    EXPECT_GT(with_three, 100u);
    EXPECT_EQ(f.extra().size(), extra);
    EXPECT_TRUE(std::is_sorted(f.extra().begin(), f.extra().end()));
  }
}

// On a real mesh cut into chunks, every corner of a chunk's owned triangle is the chunk's own
// vertex or has the chunk among its foreign chunks (what the refit needs to put it in the chunk's
// box), and no vertex lists its own chunk or a chunk whose triangles do not hold it.
TEST(ForeignChunks, HoldEveryCornerOfTheChunksOwnedTrianglesOnATorus) {
  const TriMesh m = makeTorus(1.0, 0.3, 5000);
  const MeshTopology topo(m.triangles, m.vertices.size());
  std::vector<Index> region_of(m.vertices.size());
  for (std::size_t v = 0; v < m.vertices.size(); ++v) region_of[v] = m.vertices[v].x() < 0.0 ? 0 : 1;
  const ChunkLists ch = buildChunks(topo, PositionView::of(m.vertices), region_of, 2, 32);
  std::vector<std::set<Index>> expected(m.vertices.size());
  for (Index c = 0; c < ch.count(); ++c)
    for (std::size_t k = ch.triangle_begin[c]; k < ch.triangle_begin[c + 1]; ++k)
      for (Index u : ch.triangle(c, k))
        if (ch.chunkOf(u) != c) expected[u].insert(c);
  std::size_t listed = 0, three = 0;
  for (Index v = 0; v < m.vertices.size(); ++v) {
    const std::vector<Index> got = foreignOf(ch.foreign, v);
    EXPECT_EQ(std::set<Index>(got.begin(), got.end()), expected[v]) << "vertex " << v;
    listed += got.size();
    three += got.size() > 2;
  }
  EXPECT_GT(listed, m.vertices.size() / 3) << "chunks must share their borders";
  std::cout << "[ foreign ] " << listed << " foreign entries over " << m.vertices.size() << " vertices, " << three
            << " with more than two\n";
}

// A mesh's vertices jittered by up to ±j (x) and their previous positions jittered again (q), in
// double and as Bullet-like node records: per vertex (x, y, z, pad, qx, qy, qz, pad) in single
// precision.
std::vector<std::array<float, 8>> jitteredRecords(const TriMesh& m, unsigned seed, double j, std::vector<Vec3>& x,
                                                  std::vector<Vec3>& q) {
  const std::size_t n = m.vertices.size();
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> jitter(-j, j);
  std::vector<std::array<float, 8>> f(n);
  x.resize(n);
  q.resize(n);
  for (std::size_t v = 0; v < n; ++v) {
    x[v] = m.vertices[v] + Vec3(jitter(rng), jitter(rng), jitter(rng));
    q[v] = x[v] + Vec3(jitter(rng), jitter(rng), jitter(rng));
    f[v] = {float(x[v].x()), float(x[v].y()), float(x[v].z()), 0.f, float(q[v].x()), float(q[v].y()), float(q[v].z()), 0.f};
  }
  return f;
}

// The refit's boxes against brute force on a jittered torus in Bullet-like records (single
// precision positions inside larger records, the previous ones beside them), in the fast
// single-precision pass and the generic one (double positions; with --swept): every chunk's box
// holds every corner of its owned triangles, its own vertices' previous positions with the swept
// bound, and its motion is at least its own vertices' largest |x − x_prev|. Bodies with few and
// with many chunks give the slots one and two bytes. The single-precision pass's own-vertex boxes
// (Body::chunk_own) are exactly the boxes of each chunk's own vertices.
TEST(ForeignChunks, RefitBoxesHoldEveryCornerOfTheOwnedTriangles) {
  for (const std::size_t resolution : {2000u, 20000u}) {
    const TriMesh m = makeTorus(1.0, 0.3, resolution);
    const std::size_t n = m.vertices.size();
    std::vector<Vec3> x, q;
    const std::vector<std::array<float, 8>> f = jitteredRecords(m, 11, 0.02, x, q);
    const MeshTopology topo(m.triangles, n);
    std::vector<Index> region_of(n);
    for (std::size_t v = 0; v < n; ++v) region_of[v] = m.vertices[v].x() < 0.0 ? 0 : 1;
    for (const bool single : {true, false}) {
      for (const bool swept : {false, true}) {
        Body b;
        if (single) {
          b.positions = PositionView(f[0].data(), n, sizeof f[0]);
          b.previous = PositionView(f[0].data() + 4, n, sizeof f[0]);
        } else {
          b.positions = PositionView::of(x);
          b.previous = PositionView::of(q);
        }
        b.chunks = buildChunks(topo, b.positions, region_of, 2, 32);
        b.particle_vertex = {0, 1};
        refitBounds(b, {}, swept);
        const ChunkLists& ch = b.chunks;
        ASSERT_EQ(b.chunk_box.size(), ch.count());
        // The positions as the refit reads them (single precision values are exact in double).
        const auto at = [&](Index u) { return b.positions[u]; };
        const auto before = [&](Index u) { return b.previous[u]; };
        EXPECT_EQ(ch.foreign.slotWidth(), ch.count() < 256 ? 1u : 2u);
        // The owner of each vertex is stored in the slots' width, which the refit's passes rely on.
        EXPECT_EQ(ch.owner.width(), ch.foreign.slotWidth());
        ASSERT_EQ(ch.vertexCount(), n);
        std::size_t owner_wrong = 0;
        for (Index c = 0; c < ch.count(); ++c)
          for (Index u : ch.vertices(c)) owner_wrong += ch.chunkOf(u) != c;
        EXPECT_EQ(owner_wrong, 0u);
        std::size_t outside = 0, short_motion = 0, loose = 0, long_motion = 0, own_wrong = 0;
        // The single-precision pass (not swept) also keeps each chunk's own vertices' box, exactly.
        const bool own_kept = single && !swept;
        ASSERT_EQ(b.chunk_own.size(), own_kept ? ch.count() : 0u);
        const auto holds = [](const MotionBox& box, const Vec3& p) {
          return (box.lo.array() <= p.array()).all() && (p.array() <= box.hi.array()).all();
        };
        for (Index c = 0; c < ch.count(); ++c) {
          const MotionBox& box = b.chunk_box[c];
          for (std::size_t k = ch.triangle_begin[c]; k < ch.triangle_begin[c + 1]; ++k)
            for (Index u : ch.triangle(c, k)) outside += !holds(box, at(u)) + (swept && !holds(box, before(u)));
          // Tight too: the box is exactly the smallest one around those points (the fast pass
          // only picks coordinates, as the generic one does).
          Vec3 lo = Vec3::Constant(std::numeric_limits<double>::infinity()), hi = -lo;
          const auto take = [&](Index u) {
            lo = lo.cwiseMin(at(u)).cwiseMin(swept ? before(u) : at(u));
            hi = hi.cwiseMax(at(u)).cwiseMax(swept ? before(u) : at(u));
          };
          for (std::size_t k = ch.triangle_begin[c]; k < ch.triangle_begin[c + 1]; ++k)
            for (Index u : ch.triangle(c, k)) take(u);
          double motion = 0.0;
          Vec3 own_lo = Vec3::Constant(std::numeric_limits<double>::infinity()), own_hi = -own_lo;
          for (Index u : ch.vertices(c)) {
            own_lo = own_lo.cwiseMin(at(u));
            own_hi = own_hi.cwiseMax(at(u));
          }
          if (own_kept) {
            const OwnBox& o = b.chunk_own[c];
            own_wrong += Vec3(o.lo[0], o.lo[1], o.lo[2]) != own_lo || Vec3(o.hi[0], o.hi[1], o.hi[2]) != own_hi;
          }
          for (Index u : ch.vertices(c)) {
            take(u);
            outside += !holds(box, at(u)) + (swept && !holds(box, before(u)));
            if (!swept) short_motion += box.motion < (at(u) - before(u)).norm() * (1.0 - 1e-6);
            motion = std::max(motion, (at(u) - before(u)).norm());
          }
          loose += box.lo != lo || box.hi != hi;
          if (!swept) long_motion += box.motion > motion * (1.0 + 2e-6);
        }
        EXPECT_EQ(outside, 0u) << resolution << (single ? " single" : " double") << (swept ? " swept" : "");
        EXPECT_EQ(short_motion, 0u) << resolution << (single ? " single" : " double");
        EXPECT_EQ(loose, 0u) << resolution << (single ? " single" : " double") << (swept ? " swept" : "");
        EXPECT_EQ(long_motion, 0u) << resolution << (single ? " single" : " double");
        EXPECT_EQ(own_wrong, 0u) << resolution;
      }
    }
  }
}

// The rest-shape bound's part of the refit (self-collision, RestFit in src/body.h) on Bullet-like
// single-precision records: the AVX2 pass (streamBoxesFloatRestFit) and the generic one
// (RestFitPass, what runs without AVX2) must give the same bits for everything the bound reads:
// the y-boxes, the displacement boxes, the sums of the fit and so the rotations, over two steps
// of a turned, jittered torus (the second step with the rotations fitted in the first). The chunk
// boxes are the same; their motion is the fast pass's single-precision one, raised by up to 1e-6
// relative and never below. Slots of one and two bytes, vertices of two regions. A rest shape kept
// in double (RestShape: positions given in double) takes the generic pass even with AVX2, to the
// same bits.
TEST(ForeignChunks, RestFitPassGivesTheSameBitsWithAndWithoutAvx2) {
  if (!avx2ProbesAvailable()) GTEST_SKIP() << "no AVX2 on this processor: only the generic pass runs";
  for (const std::size_t resolution : {2000u, 20000u}) {
    const TriMesh m = makeTorus(1.0, 0.3, resolution);
    const std::size_t n = m.vertices.size();
    const MeshTopology topo(m.triangles, n);
    std::vector<Index> region_of(n);
    for (std::size_t v = 0; v < n; ++v) region_of[v] = m.vertices[v].x() < 0.0 ? 0 : 1;
    const Eigen::Matrix3d turn[2] = {Eigen::AngleAxisd(0.4, Vec3(1, 2, 3).normalized()).toRotationMatrix(),
                                     Eigen::AngleAxisd(0.45, Vec3(1, 2, 2.5).normalized()).toRotationMatrix()};
    std::vector<std::array<float, 8>> records[2];
    for (int step = 0; step < 2; ++step) {
      TriMesh moved = m;
      for (Vec3& p : moved.vertices) p = turn[step] * p + Vec3(0.3, -1.0, 0.2 * step);
      std::vector<Vec3> x, q;
      records[step] = jitteredRecords(moved, 3 + step, 0.01, x, q);
    }
    // The rest shape in single precision, as the plugin's bodies keep it (RestShape): the AVX2
    // pass needs it so.
    std::vector<float> rest(3 * n);
    for (std::size_t v = 0; v < n; ++v)
      for (int j = 0; j < 3; ++j) rest[3 * v + j] = static_cast<float>(m.vertices[v][j]);
    // A third body keeps the same rest values in double (positions given in double when
    // self-collision was switched on, single precision since): the generic pass, AVX2 or not.
    std::vector<Vec3> rest_d(n);
    for (std::size_t v = 0; v < n; ++v) rest_d[v] = Vec3(rest[3 * v], rest[3 * v + 1], rest[3 * v + 2]);
    Body bodies[3];
    for (int k = 0; k < 3; ++k) {
      allowAvx2Probes(k >= 1);
      Body& b = bodies[k];
      b.rest = k < 2 ? RestShape(PositionView(rest.data(), n)) : RestShape(PositionView::of(rest_d));
      ASSERT_EQ(b.rest.single() != nullptr, k < 2);
      ASSERT_EQ(b.rest[n - 1], rest_d[n - 1]);
      b.rest_mean_edge = 0.05;
      b.chunks = buildChunks(topo, PositionView::of(m.vertices), region_of, 2, 32);
      b.particle_vertex = {0, 1};
      for (const std::vector<std::array<float, 8>>& f : records) {
        b.positions = PositionView(f[0].data(), n, sizeof f[0]);
        b.previous = PositionView(f[0].data() + 4, n, sizeof f[0]);
        refitBounds(b, {}, false, true);
      }
    }
    allowAvx2Probes(true);
    const Body& wide = bodies[1];
    const Body& narrow = bodies[0];
    ASSERT_TRUE(wide.rest_fit && narrow.rest_fit && bodies[2].rest_fit);
    {
      const RestFit& d = *bodies[2].rest_fit;
      const RestFit& g = *narrow.rest_fit;
      EXPECT_TRUE(d.chunk_lo == g.chunk_lo && d.chunk_hi == g.chunk_hi && d.rot == g.rot &&
                  d.region_xr == g.region_xr && d.next_rot == g.next_rot)
          << resolution << ": a rest shape in double must give the single one's bits";
    }
    const RestFit& a = *wide.rest_fit;
    const RestFit& g = *narrow.rest_fit;
    ASSERT_TRUE(a.filled && g.filled);
    EXPECT_EQ(wide.chunks.foreign.slotWidth(), wide.chunks.count() < 256 ? 1u : 2u);
    EXPECT_TRUE(a.chunk_lo == g.chunk_lo && a.chunk_hi == g.chunk_hi) << resolution;
    EXPECT_TRUE(a.move_lo == g.move_lo && a.move_hi == g.move_hi) << resolution;
    EXPECT_TRUE(a.region_sum_x == g.region_sum_x && a.region_xr == g.region_xr) << resolution;
    EXPECT_TRUE(a.sum_motion == g.sum_motion && a.moved == g.moved && a.mean_motion == g.mean_motion) << resolution;
    EXPECT_TRUE(a.rot == g.rot && a.next_rot == g.next_rot) << resolution;
    EXPECT_TRUE(a.chunk_center == g.chunk_center && a.chunk_half == g.chunk_half) << resolution;
    EXPECT_FALSE(g.rot[0].isIdentity(1e-3)) << "the fit follows the turn";
    ASSERT_EQ(wide.chunk_box.size(), narrow.chunk_box.size());
    std::size_t differ = 0, motion_out = 0;
    for (std::size_t c = 0; c < wide.chunk_box.size(); ++c) {
      const MotionBox& w = wide.chunk_box[c];
      const MotionBox& o = narrow.chunk_box[c];
      differ += w.lo != o.lo || w.hi != o.hi;
      motion_out += w.motion < o.motion || w.motion > o.motion * (1.0 + 1e-6);
    }
    EXPECT_EQ(differ, 0u) << resolution;
    EXPECT_EQ(motion_out, 0u) << resolution;
  }
}

// The repartition check's measures from the refit's pass (a full measure, every chunk sampled):
// each region's area is the sum of its chunks' triangle areas and max_edge the longest triangle edge, against Eigen's
// own cross products and norms on the positions as read (a relative 1e-12 for the sums, whose
// order differs); single-precision records go through the fast pass and, with AVX2, through four
// triangles at a time, which must give the scalar path's very bits.
TEST(ForeignChunks, RefitMeasuresRegionAreasAndTheLongestEdge) {
  for (const std::size_t resolution : {2000u, 20000u}) {
    const TriMesh m = makeTorus(1.0, 0.3, resolution);
    const std::size_t n = m.vertices.size();
    std::vector<Vec3> x, q;
    const std::vector<std::array<float, 8>> f = jitteredRecords(m, 5, 0.03, x, q);
    const MeshTopology topo(m.triangles, n);
    std::vector<Index> region_of(n);
    for (std::size_t v = 0; v < n; ++v) region_of[v] = m.vertices[v].x() < 0.0 ? 0 : m.vertices[v].y() < 0.0 ? 1 : 2;
    for (const bool single : {true, false}) {
      std::vector<double> areas[2];
      double edges[2] = {0.0, 0.0};
      for (const bool avx2 : {true, false}) {
        allowAvx2Probes(avx2);
        Body b;
        b.positions = single ? PositionView(f[0].data(), n, sizeof f[0]) : PositionView::of(x);
        b.chunks = buildChunks(topo, b.positions, region_of, 3, 32);
        b.particle_vertex = {0, 1, 2};
        refitBounds(b, {Measure::Full, 0}, false);
        allowAvx2Probes(true);
        const ChunkLists& ch = b.chunks;
        std::vector<double> brute(3, 0.0);
        double longest = 0.0;
        for (Index c = 0; c < ch.count(); ++c)
          for (std::size_t k = ch.triangle_begin[c]; k < ch.triangle_begin[c + 1]; ++k) {
            const Triangle t = ch.triangle(c, k);
            const Vec3 u0 = b.positions[t[0]], u1 = b.positions[t[1]], u2 = b.positions[t[2]];
            brute[ch.region_of[c]] += 0.5 * (u1 - u0).cross(u2 - u0).norm();
            longest = std::max({longest, (u1 - u0).norm(), (u2 - u0).norm(), (u2 - u1).norm()});
          }
        ASSERT_EQ(b.shape.region_area.size(), 3u);
        for (int r = 0; r < 3; ++r) {
          EXPECT_GT(brute[r], 0.5) << r;
          EXPECT_NEAR(b.shape.region_area[r], brute[r], 1e-12 * brute[r]) << resolution << " region " << r;
        }
        EXPECT_NEAR(b.shape.max_edge, longest, 1e-12 * longest) << resolution;
        areas[avx2 ? 1 : 0] = b.shape.region_area;
        edges[avx2 ? 1 : 0] = b.shape.max_edge;
      }
      for (int r = 0; r < 3; ++r) EXPECT_EQ(areas[0][r], areas[1][r]) << resolution << " region " << r;
      EXPECT_EQ(edges[0], edges[1]) << resolution;
    }
  }
}

// The check's sampled areas (RepartitionSettings::area_sample_chunks): each region's area from
// every k-th of its chunks, their area now times the region's over theirs in the reference (a full
// measure at partitioning). The very sum, to the bit, where k is 1 or the reference is missing;
// the exact area for the reference's own positions; with AVX2 and without the same bits; and on a
// body stretched unevenly (by 1.5 along x, so each chunk's area grows by its own factor) the
// trigger's ratio, area now over A*, within a few percent of the true one.
TEST(ForeignChunks, SampledRegionAreasEstimateTheTrueAreas) {
  const TriMesh m = makeTorus(1.0, 0.3, 20000);
  const std::size_t n = m.vertices.size();
  std::vector<Vec3> x, q;
  const std::vector<std::array<float, 8>> f = jitteredRecords(m, 7, 0.03, x, q);
  std::vector<std::array<float, 8>> g = f;
  for (auto& r : g) r[0] *= 1.5f;
  const MeshTopology topo(m.triangles, n);
  std::vector<Index> region_of(n);
  for (std::size_t v = 0; v < n; ++v) region_of[v] = m.vertices[v].x() < 0.0 ? 0 : m.vertices[v].y() < 0.0 ? 1 : 2;
  Body b;
  b.positions = PositionView(f[0].data(), n, sizeof f[0]);
  b.chunks = buildChunks(topo, b.positions, region_of, 3, 32);
  b.particle_vertex = {0, 1, 2};
  const ChunkLists& ch = b.chunks;
  Index most = 0, fewest = static_cast<Index>(ch.count());
  for (Index r = 0; r < 3; ++r) {
    most = std::max(most, ch.region_begin[r + 1] - ch.region_begin[r]);
    fewest = std::min(fewest, ch.region_begin[r + 1] - ch.region_begin[r]);
  }
  ASSERT_GE(fewest, 100u);  // so that a sample of 8 leaves out most chunks
  const auto measure = [&](const std::vector<std::array<float, 8>>& records, Measure how, bool avx2) {
    allowAvx2Probes(avx2);
    b.positions = PositionView(records[0].data(), n, sizeof records[0]);
    refitBounds(b, how, false);
    allowAvx2Probes(true);
    return b.shape;
  };
  std::vector<double> estimates[2];
  for (const bool avx2 : {true, false}) {
    b.chunk_area_ref.clear();
    const ShapeFigures exact = measure(f, {Measure::Full, 8}, avx2);
    const ShapeFigures stretched_exact = measure(g, {Measure::Full, 8}, avx2);
    ASSERT_EQ(exact.chunk_area.size(), ch.count());
    // No reference yet: a sampled measure reads every chunk.
    EXPECT_EQ(measure(f, {Measure::Sampled, 8}, avx2).region_area, exact.region_area) << avx2;
    b.chunk_area_ref = exact.chunk_area;
    // k = 1 in every region: the sums themselves.
    EXPECT_EQ(measure(g, {Measure::Sampled, most}, avx2).region_area, stretched_exact.region_area) << avx2;
    const ShapeFigures same = measure(f, {Measure::Sampled, 8}, avx2);
    const ShapeFigures stretched = measure(g, {Measure::Sampled, 8}, avx2);
    EXPECT_LE(stretched.max_edge, stretched_exact.max_edge) << avx2;
    EXPECT_TRUE(stretched.chunk_area.empty());
    for (int r = 0; r < 3; ++r) {
      EXPECT_NEAR(same.region_area[r], exact.region_area[r], 1e-12 * exact.region_area[r]) << avx2 << " region " << r;
      const double ratio = stretched.region_area[r] / exact.region_area[r];
      const double truth = stretched_exact.region_area[r] / exact.region_area[r];
      EXPECT_GT(truth, 1.15) << r;
      EXPECT_NE(stretched.region_area[r], stretched_exact.region_area[r]) << avx2 << " region " << r;
      EXPECT_NEAR(ratio, truth, 0.02 * truth) << avx2 << " region " << r;
    }
    estimates[avx2 ? 1 : 0] = stretched.region_area;
  }
  EXPECT_EQ(estimates[0], estimates[1]);
}

}  // namespace
}  // namespace psc::detail
