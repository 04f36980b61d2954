#include "ground_truth.h"

#include <algorithm>
#include <cstdio>
#include <set>
#include <utility>

namespace psc_test {
namespace {

Vec3 toVec(const btVector3& v) { return {double(v.x()), double(v.y()), double(v.z())}; }

struct BodyCache {
  std::vector<Vec3> x;
  std::vector<double> motion;  // |x − q|
  std::vector<psc::Triangle> faces;  // node indices
  std::vector<Vec3> face_lo, face_hi;
  std::vector<bool> degenerate;
  Vec3 lo, hi;
  double max_motion = 0.0;
  double margin = 0.0;
};

BodyCache cacheOf(const btSoftBody& body) {
  BodyCache c;
  c.margin = body.getCollisionShape()->getMargin();
  const int n = body.m_nodes.size();
  c.x.resize(n);
  c.motion.resize(n);
  c.lo = Vec3::Constant(1e300);
  c.hi = Vec3::Constant(-1e300);
  for (int i = 0; i < n; ++i) {
    c.x[i] = toVec(body.m_nodes[i].m_x);
    c.motion[i] = (toVec(body.m_nodes[i].m_x) - toVec(body.m_nodes[i].m_q)).norm();
    c.max_motion = std::max(c.max_motion, c.motion[i]);
    c.lo = c.lo.cwiseMin(c.x[i]);
    c.hi = c.hi.cwiseMax(c.x[i]);
  }
  const btSoftBody::Node* first = n > 0 ? &body.m_nodes[0] : nullptr;
  const int f = body.m_faces.size();
  c.faces.resize(f);
  c.face_lo.resize(f);
  c.face_hi.resize(f);
  c.degenerate.resize(f);
  for (int t = 0; t < f; ++t) {
    const btSoftBody::Face& face = body.m_faces[t];
    for (int k = 0; k < 3; ++k) c.faces[t][k] = static_cast<psc::Index>(face.m_n[k] - first);
    Vec3 lo = c.x[c.faces[t][0]], hi = lo;
    for (int k = 1; k < 3; ++k) {
      lo = lo.cwiseMin(c.x[c.faces[t][k]]);
      hi = hi.cwiseMax(c.x[c.faces[t][k]]);
    }
    c.face_lo[t] = lo;
    c.face_hi[t] = hi;
    // Bullet's ProjectOrigin skips faces whose |cross|² is not above SIMD_EPSILON (in btScalar).
    const btVector3 q = btCross(face.m_n[1]->m_x - face.m_n[0]->m_x, face.m_n[2]->m_x - face.m_n[0]->m_x);
    c.degenerate[t] = !(q.length2() > SIMD_EPSILON);
  }
  return c;
}

double pointBoxDistance(const Vec3& p, const Vec3& lo, const Vec3& hi) {
  return (p.cwiseMax(lo).cwiseMin(hi) - p).norm();
}

GroundTruth compute(const btAlignedObjectArray<btSoftBody*>& bodies, bool prefilter) {
  std::vector<BodyCache> caches;
  for (int i = 0; i < bodies.size(); ++i) caches.push_back(cacheOf(*bodies[i]));
  GroundTruth truth;
  for (int b = 0; b < bodies.size(); ++b)
    truth.degenerate_faces += static_cast<std::size_t>(std::count(caches[b].degenerate.begin(), caches[b].degenerate.end(), true));
  for (int a = 0; a < bodies.size(); ++a) {
    const BodyCache& A = caches[a];
    for (int b = 0; b < bodies.size(); ++b) {
      if (a == b) continue;
      const BodyCache& B = caches[b];
      const double strict = A.margin + B.margin;
      const double reach = (strict + 2.0 * A.max_motion) * (1.0 + kRadiusTolerance) + 1e-6;
      if (prefilter && ((A.lo.array() - reach > B.hi.array()).any() || (B.lo.array() > A.hi.array() + reach).any()))
        continue;
      const auto full = [&](psc::Index v) { return strict + 2.0 * A.motion[v]; };
      const auto allowed = [&](psc::Index v) { return full(v) * (1.0 + kRadiusTolerance) + 1e-6; };
      const auto skip = [&](psc::Index v, psc::Index t) {
        return B.degenerate[t] || (prefilter && pointBoxDistance(A.x[v], B.face_lo[t], B.face_hi[t]) >= allowed(v));
      };
      psc::testkit::forEachContact(A.x, B.x, B.faces, allowed, skip, [&](psc::Index v, psc::Index t, double d) {
        const ContactKey key{a, int(v), b, int(t)};
        truth.allowed.push_back(key);
        if (d < full(v) * (1.0 - kRadiusTolerance)) truth.full.push_back(key);
        if (d < strict * (1.0 - kRadiusTolerance)) truth.strict.push_back(key);
      });
    }
  }
  std::sort(truth.strict.begin(), truth.strict.end());
  std::sort(truth.full.begin(), truth.full.end());
  std::sort(truth.allowed.begin(), truth.allowed.end());
  return truth;
}

std::size_t countIn(const std::vector<ContactKey>& sorted_truth, const std::vector<ContactKey>& sorted_found) {
  std::vector<ContactKey> both;
  std::set_intersection(sorted_truth.begin(), sorted_truth.end(), sorted_found.begin(), sorted_found.end(),
                        std::back_inserter(both));
  return both.size();
}

std::set<std::pair<int, int>> bodyPairs(const std::vector<ContactKey>& keys) {
  std::set<std::pair<int, int>> pairs;
  for (const ContactKey& k : keys) pairs.insert({std::min(k.node_body, k.face_body), std::max(k.node_body, k.face_body)});
  return pairs;
}

}  // namespace

GroundTruth bruteForceContacts(const btAlignedObjectArray<btSoftBody*>& bodies) { return compute(bodies, true); }
GroundTruth bruteForceContactsNoPrefilter(const btAlignedObjectArray<btSoftBody*>& bodies) {
  return compute(bodies, false);
}

std::vector<ContactKey> foundContacts(const btAlignedObjectArray<btSoftBody*>& bodies) {
  std::vector<ContactKey> found;
  for (int a = 0; a < bodies.size(); ++a) {
    const btSoftBody& body = *bodies[a];
    for (int i = 0; i < body.m_scontacts.size(); ++i) {
      const btSoftBody::SContact& c = body.m_scontacts[i];
      ContactKey key{a, int(c.m_node - &body.m_nodes[0]), -1, -1};
      for (int b = 0; b < bodies.size(); ++b) {
        const btSoftBody& other = *bodies[b];
        if (other.m_faces.size() > 0 && c.m_face >= &other.m_faces[0] && c.m_face < &other.m_faces[0] + other.m_faces.size()) {
          key.face_body = b;
          key.face = int(c.m_face - &other.m_faces[0]);
        }
      }
      found.push_back(key);
    }
  }
  std::sort(found.begin(), found.end());
  return found;
}

void RecallMeter::add(const GroundTruth& truth, const std::vector<ContactKey>& found) {
  ++steps_;
  found_ += found.size();
  degenerate_ = std::max(degenerate_, truth.degenerate_faces);
  const std::size_t hit_strict = countIn(truth.strict, found);
  const std::size_t hit_full = countIn(truth.full, found);
  truth_strict_ += truth.strict.size();
  hit_strict_ += hit_strict;
  truth_full_ += truth.full.size();
  hit_full_ += hit_full;
  if (!truth.strict.empty()) worst_strict_ = std::min(worst_strict_, double(hit_strict) / double(truth.strict.size()));
  if (!truth.full.empty()) worst_full_ = std::min(worst_full_, double(hit_full) / double(truth.full.size()));
  false_ += found.size() - countIn(truth.allowed, found);
  const auto true_pairs = bodyPairs(truth.strict);
  const auto found_pairs = bodyPairs(found);
  pairs_true_ += true_pairs.size();
  for (const auto& p : true_pairs) pairs_hit_ += found_pairs.count(p);
}

std::string RecallMeter::line(const std::string& scene, const std::string& pipeline) const {
  char buffer[512];
  std::snprintf(buffer, sizeof buffer,
                "recall %-14s %-7s steps=%zu strict=%.4f (%zu/%zu, worst step %.4f) full=%.4f (%zu/%zu, worst step "
                "%.4f) body-pairs=%.4f found=%zu false=%zu",
                scene.c_str(), pipeline.c_str(), steps_, strictRecall(), truth_strict_ - missedStrict(), truth_strict_,
                worst_strict_, fullRecall(), truth_full_ - missedFull(), truth_full_, worst_full_, pairRecall(), found_,
                false_);
  return buffer;
}

}  // namespace psc_test
