// The exact (node, face) tests behind Settings::exact, callable on any pair: the plugin runs them
// on the core's candidates; tests and benchmarks call them directly.
//
// Every test decides for a node of one soft body against a face of another, exactly where
// btSoftColliders::CollideVF_SS decides (margin = both bodies' collision margins, positions m_x
// after predictMotion, previous positions m_q), and fills a btSoftBody::SContact the way
// CollideVF_SS fills it, for Bullet's own solver (btSoftBody::PSolve_SContacts).
#pragma once

#include "psc/bullet/precision.h"
#include "psc/bullet/settings.h"
#include "psc/types.h"
#include "psc/world.h"

#include <BulletSoftBody/btSoftBody.h>

#include <array>
#include <optional>
#include <string>

namespace psc::bullet {

/// "bullet", "robust", "continuous".
const char* toString(ExactTest test);
/// The inverse of toString; throws psc::Error(InvalidArgument) naming the text otherwise.
ExactTest exactTestFromString(const std::string& text);

/// Which rule made a contact.
enum class ContactKind {
  None,      ///< no contact
  Bullet,    ///< CollideVF_SS's own contact (bit for bit)
  Robust,    ///< Bullet refused or had no finite normal; the closest point (ExactTest::Robust)
  Crossing,  ///< Continuous: the node passed through the face during the step
};

/// Runs `test` on node `node` of `node_body` against face `face` of `face_body` (different
/// bodies). On a contact, writes it to `contact` (what CollideVF_SS would push into
/// node_body.m_scontacts) and returns its kind; otherwise returns None and leaves `contact` alone.
/// A pair with a non-finite position (m_x or m_q of the node or of a corner) or margin has no
/// contact, whatever the test: Bullet's own test reads a point it never set there, and a NaN
/// normal would carry into the solver.
ContactKind exactContact(ExactTest test, const btSoftBody& node_body, const btSoftBody::Node& node,
                         const btSoftBody& face_body, const btSoftBody::Face& face, btSoftBody::SContact& contact);

/// What collideCandidates did.
struct ExactCounts {
  std::size_t tests = 0;      ///< pairs tested
  std::size_t contacts = 0;   ///< SContacts appended
  std::size_t robust = 0;     ///< of them: ContactKind::Robust (pairs Bullet's test refuses or has no normal for)
  std::size_t crossings = 0;  ///< of them: ContactKind::Crossing
  std::size_t turned = 0;     ///< Continuous: discrete contacts of nodes that crossed a face of the same body, given the face's normal
  std::size_t dropped = 0;    ///< Continuous: such contacts on degenerate faces (no normal), removed
  std::size_t reduced = 0;    ///< ContactSet::NearestFace: accepted contacts removed (not their node's nearest)
};

/// The plugin's exact stage for one direction of one body pair: runs `test` on each candidate
/// (node `vertex` of node_body, face `triangle` of face_body) in [first, last) and appends the
/// contacts to node_body.m_scontacts, in candidate order. Bullet runs btSoftColliders::CollideVF_SS
/// itself; with single-precision Bullet on a processor with AVX, all three run their discrete
/// test eight pairs at a time, the same float operations in the same order (the same bits).
/// Continuous then turns the discrete contacts of every node that got a crossing contact
/// here to their face's normal on the side the node started from (the side at m_q, at the
/// contact's weights): decided from behind the surface, their closest-point normals would push it
/// further through; kept, they hold it in front of the faces next to the crossed one, which the
/// solver otherwise moves it through where the surface is folded. Contacts on degenerate faces
/// (no normal) are dropped.
/// With ContactSet::NearestFace, of each node's contacts of this call only the discrete one
/// nearest to the node (|m_x − the face point at the contact's weights|, in btScalar; the first of
/// equals) and its crossing contacts stay, in candidate order; ExactCounts::reduced counts the rest.
/// The candidates' indices must be valid for the bodies' m_nodes / m_faces (psc::Error otherwise,
/// before any contact is made), and their positions
/// and margins finite (the plugin leaves a body with a non-finite node out of the sensors, so no
/// candidate of it comes here; exactContact checks it per pair).
ExactCounts collideCandidates(ExactTest test, btSoftBody& node_body, btSoftBody& face_body,
                              const psc::CandidatePair* first, const psc::CandidatePair* last,
                              ContactSet contacts = ContactSet::AllPairs);
/// The same at a given contact radius (what takes the place of the two margins' sum, the motion
/// term still added): a body against itself at its self contact radius
/// (psc::SensorWorld::selfRadius) rather than at twice its margin. Contacts carry it as m_margin.
/// Continuous on a body against itself (node_body == face_body) adds no motion term: its discrete
/// radius is `radius` alone, and its crossing test stands for the motion.
ExactCounts collideCandidates(ExactTest test, btSoftBody& node_body, btSoftBody& face_body, btScalar radius,
                              const psc::CandidatePair* first, const psc::CandidatePair* last,
                              ContactSet contacts = ContactSet::AllPairs);

/// [beyond] Settings::runaway_sharing and Settings::crowded_band on node_body.m_scontacts[from,
/// end), the contacts of one direction of one body pair made at contact radius `radius` (the
/// margins' sum). A contact lies in the band when it was accepted at more than `radius` (m_margin >
/// radius: not a Continuous crossing contact, made at the margins) and its node is at least
/// `radius` from its face point (at the contact's weights, in btScalar). Each node with more than max(above, 1) contacts in the
/// band has their m_cfm[0] and m_cfm[1] divided by that number, so that together they weigh what
/// one contact does. Contacts within the radius, and the band contacts of nodes with fewer, are
/// left as they are. `above` = 1: every node with two or more (a pair that ran away); 32: only
/// crowded nodes. Returns how many contacts were changed.
std::size_t shareBandWeights(btSoftBody& node_body, int from, btScalar radius, std::size_t above = 1);

// --- the geometry, in double -------------------------------------------------------------------

/// The closest point of triangle (a, b, c) to p as barycentric weights (≥ 0, sum 1; weights[i]
/// belongs to the i-th vertex) and its squared distance. Exact up to double rounding for any
/// triangle, degenerate ones included (they are reduced to their edges by a test relative to their
/// own size, so the answer does not depend on the unit of length).
struct ClosestPoint {
  double distance2 = 0.0;
  std::array<double, 3> weights{};
};
ClosestPoint closestPointOnTriangle(const Vec3& p, const Vec3& a, const Vec3& b, const Vec3& c);

/// Where a moving point first meets a moving triangle.
struct Crossing {
  double t = 0.0;                  ///< fraction of the step, in [0, 1]
  std::array<double, 3> weights{}; ///< barycentric weights of the meeting point on the triangle at t
  /// How many times after t, up to the step's end, the point passes back through the triangle
  /// (a later sign change of the coplanarity with the point within kCrossingTolerance of it): odd
  /// when it came back through the triangle to the side it started on.
  int returns = 0;
};

/// Relative tolerance of firstCrossing's inside test: the point counts as on the triangle when its
/// distance to it is at most this times the triangle's longest edge at that time.
inline constexpr double kCrossingTolerance = 1e-6;

/// The point moves linearly from start[0] to end[0] and the triangle's vertices i = 1..3 from
/// start[i] to end[i]. Returns the first t in [0, 1] at which the point lies in the triangle's plane
/// (a root of the coplanarity cubic: a sign change, or a touch within rounding) and within
/// kCrossingTolerance of the triangle. A motion that stays coplanar for the whole step has no
/// crossing (it never changes side; the discrete test sees it). Scale-invariant.
/// A crossing implies that the box of the point's segment meets the box of the six triangle
/// positions (the swept triangle lies in their convex hull): the midphase condition for soundness.
std::optional<Crossing> firstCrossing(const std::array<Vec3, 4>& start, const std::array<Vec3, 4>& end);

}  // namespace psc::bullet
