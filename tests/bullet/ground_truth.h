// Exact brute-force ground truth for soft-soft vertex-face contacts (docs/BENCHMARK.md): node v of body
// A and face t of body B ≠ A are in contact when the exact distance from x_v to triangle t is
// below a radius, strict = margin_A + margin_B, full = strict + 2·|x_v − q_v| (Bullet's
// CollideVF_SS acceptance). Both directions. Independent of the plugin and of the core: it shares
// no candidate-finding code with either (the distance and the brute-force loop are psc::testkit's).
#pragma once

#include "psc/testkit/reference.h"

#include <BulletSoftBody/btSoftBody.h>

#include <Eigen/Core>

#include <cstddef>
#include <string>
#include <tuple>
#include <vector>

namespace psc_test {

using Vec3 = Eigen::Vector3d;

/// The exact point-triangle distance in double (psc::testkit).
using psc::testkit::pointTriangleDistance;

/// A (node, face) contact; bodies are indices into the soft body array the contacts came from.
struct ContactKey {
  int node_body = 0;
  int node = 0;
  int face_body = 0;
  int face = 0;
  bool operator<(const ContactKey& o) const {
    return std::tie(node_body, face_body, node, face) < std::tie(o.node_body, o.face_body, o.node, o.face);
  }
  bool operator==(const ContactKey& o) const {
    return node_body == o.node_body && node == o.node && face_body == o.face_body && face == o.face;
  }
};

struct GroundTruth {
  std::vector<ContactKey> strict;   ///< sorted; distance < strict radius·(1 − tolerance)
  std::vector<ContactKey> full;     ///< sorted; distance < full radius·(1 − tolerance)
  std::vector<ContactKey> allowed;  ///< sorted; distance < full radius·(1 + tolerance) + 1e-6: what an exact stage may report
  std::size_t degenerate_faces = 0; ///< faces Bullet's ProjectOrigin cannot test (|cross|² ≤ SIMD_EPSILON), left out
};

/// Relative tolerance at the radius boundary: Bullet decides in btScalar (float by default), the
/// truth in double; contacts within this band of the radius count neither as missed nor as false.
inline constexpr double kRadiusTolerance = 1e-4;

/// Every body against every other, every node against every face; a body-box and a face-box
/// prefilter skip only pairs that are provably farther than the radius.
GroundTruth bruteForceContacts(const btAlignedObjectArray<btSoftBody*>& bodies);
/// The same without any prefilter (for checking the prefilter itself).
GroundTruth bruteForceContactsNoPrefilter(const btAlignedObjectArray<btSoftBody*>& bodies);

/// The (node, face) pairs in the bodies' m_scontacts, sorted. -1 face body when the face belongs
/// to none of the bodies (a bug).
std::vector<ContactKey> foundContacts(const btAlignedObjectArray<btSoftBody*>& bodies);

/// Recall bookkeeping over the steps of one run of one pipeline.
class RecallMeter {
 public:
  void add(const GroundTruth& truth, const std::vector<ContactKey>& found);

  double strictRecall() const { return ratio(hit_strict_, truth_strict_); }
  double fullRecall() const { return ratio(hit_full_, truth_full_); }
  double worstStrictStep() const { return worst_strict_; }
  double worstFullStep() const { return worst_full_; }
  double pairRecall() const { return ratio(pairs_hit_, pairs_true_); }
  std::size_t truthStrict() const { return truth_strict_; }
  std::size_t truthFull() const { return truth_full_; }
  std::size_t missedStrict() const { return truth_strict_ - hit_strict_; }
  std::size_t missedFull() const { return truth_full_ - hit_full_; }
  std::size_t falseContacts() const { return false_; }
  std::size_t found() const { return found_; }
  std::size_t steps() const { return steps_; }
  std::size_t degenerateFaces() const { return degenerate_; }
  /// One line: "recall <scene> <pipeline> steps=… strict=… full=… …".
  std::string line(const std::string& scene, const std::string& pipeline) const;

 private:
  static double ratio(std::size_t a, std::size_t b) { return b == 0 ? 1.0 : double(a) / double(b); }
  std::size_t truth_strict_ = 0, hit_strict_ = 0, truth_full_ = 0, hit_full_ = 0;
  std::size_t pairs_true_ = 0, pairs_hit_ = 0, false_ = 0, found_ = 0, steps_ = 0, degenerate_ = 0;
  double worst_strict_ = 1.0, worst_full_ = 1.0;
};

}  // namespace psc_test
