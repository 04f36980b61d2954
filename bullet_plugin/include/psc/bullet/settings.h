// Settings of the Bullet plugin. Defaults live here, units in the comments.
#pragma once

#include "psc/bullet/precision.h"
#include "psc/settings.h"

namespace psc::bullet {

/// Which soft bodies the particle sensors handle when no per-body choice was made with
/// Plugin::setEnabled(). A soft-soft pair goes to the sensors only when both bodies participate;
/// any other pair is handed, unchanged, to the algorithm Bullet had registered before install()
/// (by default btSoftSoftCollisionAlgorithm, i.e. btSoftBody::defaultCollisionHandler).
enum class OptIn {
  /// A body participates when `m_cfg.collisions` contains btSoftBody::fCollision::VF_SS, the flag
  /// that already switches on Bullet's own vertex-face soft-soft collision (off by default).
  /// Existing programs keep their meaning: the pairs Bullet collided are now collided by sensors.
  VfSsFlag,
  /// Only bodies passed to Plugin::setEnabled(body, true) participate; their VF_SS flag is not
  /// needed. Leaving VF_SS off also spares Bullet's per-step refit of the body's face tree.
  Explicit,
};

/// The exact (node, face) test the plugin runs on each of the core's candidate pairs. Costs per
/// test and what each guarantees: README "Exact tests"; the functions themselves: exact.h.
enum class ExactTest {
  /// Bullet's own btSoftColliders::CollideVF_SS, unchanged: the contacts of Bullet's default path
  /// (whose weights Settings::runaway_sharing and crowded_band may then share, m_cfm divided, and
  /// whose margin a self contact gets from the self rule: README "Contact set", docs/METHOD.md §6.3).
  /// It refuses every face with |cross|² ≤ SIMD_EPSILON (area below ~1.7e-4 units² in float).
  Bullet,
  /// Bullet's contact, bit for bit, wherever CollideVF_SS accepts the pair (except that a node
  /// lying exactly on the face gets a finite normal instead of Bullet's 0/0); where Bullet's
  /// arithmetic skipped the face or an edge as too small, the closest point computed relative to
  /// the node with relative thresholds, so no contact depends on the unit of length or on where
  /// the bodies are: in single precision with single-precision Bullet (rounded relative to the face
  /// and the distance), in double (exact) for slivers, tiny or huge faces and nodes almost on the
  /// face, and with double-precision Bullet.
  Robust,
  /// Robust's test (Bullet's radius, margins + 2·|m_x − m_q|), plus a continuous test over the
  /// step (m_q → m_x, linear motion of the node and of the face's nodes): a node that passes
  /// through the face during the step gets a contact that pushes it back to the side it came from
  /// (instead of Bullet's, whose normal points through), at the margins. Its discrete contacts
  /// against the same body keep their weights but take their face's normal towards the side the
  /// node started on, so the faces next to the crossed one (a dent under an impact) hold it too
  /// (exact.h). runaway_sharing and crowded_band apply to its discrete contacts as to Robust's.
  /// With `sensors.motion_bound` = Radius (the default) the plugin asks the core for every pair
  /// within Bullet's radius and every pair that meets within the margins during the step
  /// (psc::SensorSettings::meeting_pairs), so between two bodies it makes every contact Robust
  /// makes and its crossing test sees every pair that can cross. A body against itself
  /// (self-collision): the self rule's candidates, its discrete test at the self radius alone (a
  /// body's speed is no reason to touch itself), and the crossing test. With Swept
  /// only the pairs that meet, so a pair within Bullet's radius that does not meet gets no
  /// contact. With the thesis's flag-only mode (sensors.flagging = Sensors) it tests the thesis's
  /// candidate sets, which hold neither guarantee. Swept, with the margins alone as the
  /// discrete radius, was the only choice until 2026-11-26; on the fast scenes Bullet's radius left
  /// no edge–triangle crossing and no tunnelled vertex at 300 to 2,000 vertices, where that had
  /// both (docs/DECISIONS.md, "Continuous keeps Bullet's radius").
  Continuous,
};

/// Which of the exact test's contacts go to Bullet's solver.
enum class ContactSet {
  /// Every pair the exact test accepts, as Bullet's own path makes them: a node within the contact
  /// radius of k faces of one body gets k contacts. On fine meshes k grows as (radius / edge)²
  /// (about 50 per resting node on 8,000-vertex tori with 0.05 margins), and each pushes the node.
  AllPairs,
  /// [beyond] Per node and body it touches (its own body with self-collision), the accepted
  /// discrete contact nearest to the node (the first of equals, in face order); Continuous's
  /// crossing contacts are all kept. No node that got a contact against a body loses it; the
  /// contacts beside it, which push the same node out of the neighbouring faces' planes, go
  /// (Stats::reduced_contacts counts them; with Robust the core hands over only each node's nearest
  /// candidates, SensorSettings::nearest_candidates). Bullet's response on them feeds a runaway in
  /// a dense fine pile (README, "Not done"); with this set it did not run away.
  NearestFace,
};

/// "all", "nearest".
const char* toString(ContactSet set);

struct Settings {
  /// The core's settings (μ, R_eff, rounds, flagging, partitioning, motion bound). `sensors.motion_factor`
  /// = 2 matches the motion term of Bullet's CollideVF_SS acceptance radius; less lets the
  /// candidates fall short of what Bullet would accept for fast nodes. `sensors.motion_bound`: Radius (the default) hands Bullet's test every pair its
  /// radius accepts; on fast bodies Bullet's contact response, which pushes each contact's node out
  /// to the whole radius, can feed on them (a runaway, README "Fast bodies with Bullet's test").
  /// Ahead keeps, of those pairs, the ones within the margins and the ones the node and the face
  /// head into during the next `sensors.ahead_steps` steps: no runaway on the fast scenes, fewer
  /// tests than Bullet's own path, and still every contact within the margins; but resting bodies
  /// lose the contacts of nodes that move away or sideways, which Radius's completeness keeps.
  psc::SensorSettings sensors;
  /// [beyond] With `sensors.motion_bound` = Radius and the discrete tests (Bullet, Robust): a body
  /// pair that runs away (Stats::runaway_pairs) is put on the Ahead bound from the next step on,
  /// until its bodies' boxes part (psc::SensorWorld::setPairAhead); Stats::runaway_fallbacks counts
  /// them, and the runaway is still reported. Every other pair, and this one before its runaway,
  /// keeps the radius bound's completeness. Off by default: once on Ahead the pair no longer gets
  /// every contact Bullet's radius accepts (README, "Fast bodies with Bullet's test", for what it
  /// changes on the fast scenes).
  bool runaway_fallback = false;
  /// [beyond] With every exact test: in a body pair that runs away, the contacts
  /// that lie beyond the margins (inside Bullet's motion term, margins + 2·|m_x − m_q|) share
  /// one contact's weight per node: each one's m_cfm is divided by how many such contacts its node
  /// has against the other body (shareBandWeights, exact.h). Every contact is still made, and the
  /// contacts within the margins keep Bullet's weights. It starts on the step the pair goes over
  /// the runaway rule (that step's contacts included) and lasts until a step in which the pair has
  /// no contact. Bullet's response pushes each contact's node out to its whole radius, so a node
  /// with k contacts in the band is thrown back k times over, which grows its next motion term:
  /// that loop is the runaway. On the fast scenes it ends the runaway within a few steps, without
  /// the recall that Ahead (runaway_fallback) gives up (README, "Fast bodies with Bullet's test").
  /// Pairs that never reach the rule keep Bullet's weights, except for crowded nodes (crowded_band).
  /// false: no pair-wide sharing (crowded_band still applies unless it is 0).
  bool runaway_sharing = true;
  /// [beyond] With every exact test, in every pair of two bodies (a body's self
  /// contacts keep Bullet's weights): a node with more than this many contacts beyond the margins
  /// against the other body shares one contact's weight among them (their m_cfm divided by their
  /// count, as in a pair that ran away), from the first step, with or without a runaway. Such a
  /// node is thrown back once by each of them, and their number grows with the band's area over
  /// the faces' (π·((margins + 2·|Δx|)² − d²) / face area): fine meshes and fast nodes reach it,
  /// coarse calm piles do not. Without it, 8 tori × 8,000 vertices with `Robust` ran away at step
  /// 120 and filled the memory; with it they finish (README, "Crowded bands"). 0: off, Bullet's
  /// weights wherever the pair has not run away. 32 was chosen over 16, 24, 48 and 64 on the suite
  /// at 600, 1,000 and 2,000 vertices and five seeds of `mixed_pile` (docs/DECISIONS.md, "Crowded
  /// bands share their weight, in every pair").
  std::size_t crowded_band = 32;
  OptIn opt_in = OptIn::VfSsFlag;
  /// [beyond] Also collide participating body pairs that have candidates but were not dispatched
  /// because their broadphase boxes do not overlap. Bullet 3.24 bounds a soft body by its nodes
  /// ± its margin, while CollideVF_SS accepts out to margin_A + margin_B + 2·|m_x − m_q|: for fast
  /// nodes the broadphase alone drops contacts inside Bullet's own radius. Bullet's filtering still
  /// applies (collision groups and masks, the pair cache's overlap filter callback,
  /// btCollisionObject::checkCollideWith, deactivation). false: only dispatched pairs are collided.
  bool beyond_broadphase = true;
  /// The exact test on the candidates (see ExactTest; for Continuous, `sensors.motion_bound`
  /// decides which pairs its crossing test sees).
  ExactTest exact = ExactTest::Bullet;
  /// Which of its contacts reach the solver: all (Bullet's model, the default) or the nearest face
  /// per node and body.
  ContactSet contacts = ContactSet::AllPairs;
  /// [beyond] Self-collision (a body's nodes against its own faces, through the sensor regions)
  /// for every participating body; Plugin::setSelfCollision overrides it per body. Off keeps
  /// Bullet's behaviour: btSoftRigidDynamicsWorld has no vertex-face self-collision.
  bool self_collision = false;
};

}  // namespace psc::bullet
