// What the plugin did in one simulation step.
#pragma once

#include "psc/bullet/precision.h"
#include "psc/world.h"

#include <BulletSoftBody/btSoftBody.h>

#include <cstddef>
#include <cstdint>
#include <string>

namespace psc::bullet {

/// Counters of the most recent simulation step in which Bullet dispatched at least one soft-soft
/// pair (the sensors are stepped lazily at the first such pair; see Plugin). Complete once
/// btSoftRigidDynamicsWorld::stepSimulation() has returned.
/// The runaway rule (Stats::runaway_pairs): a soft body pair is running away when its soft-soft
/// contacts in one step exceed kRunawayContactsPerNode × (the contacts one node resting on the
/// finer of the two surfaces has: π·(margin_A + margin_B)² over its mean rest face area, at
/// least 1) × the node count of the smaller body. Resting contact measured at most ~6 contacts per
/// node over the demo's scenes; runaways reach hundreds per node.
inline constexpr std::size_t kRunawayContactsPerNode = 16;
/// The contact count above which the pair (a, b) is running away (rule above).
double runawayContacts(const btSoftBody& a, const btSoftBody& b);
/// Whether `contacts` in one step put (a, b) over the rule; reads the face areas only past
/// kRunawayContactsPerNode contacts per node of the smaller body.
bool isRunaway(const btSoftBody& a, const btSoftBody& b, std::size_t contacts);

struct Stats {
  std::uint64_t sensor_steps = 0;     ///< sensor steps since install()
  std::size_t bodies = 0;             ///< soft bodies handled by the sensors this step
  std::size_t skipped_bodies = 0;     ///< participating bodies the core cannot take (no faces, rejected mesh)
  std::size_t particles = 0;
  int rounds = 0;                     ///< particle movement rounds (Jacobi sweeps)
  std::size_t round_cap_hits = 0;     ///< 1 when SensorSettings::max_rounds stopped the movement
  std::size_t flagged_pairs = 0;      ///< flagged region pairs
  std::size_t candidate_pairs = 0;    ///< unique (node, face) pairs the core handed over, all bodies
  std::size_t repartitions = 0;       ///< bodies re-partitioned this step
  std::size_t body_pairs = 0;         ///< soft-soft pairs collided through the sensors
  std::size_t beyond_broadphase_pairs = 0;  ///< of body_pairs: collided although not dispatched (Settings::beyond_broadphase)
  std::size_t fallback_pairs = 0;     ///< soft-soft pairs handed to Bullet's previous algorithm
  std::size_t exact_tests = 0;        ///< CollideVF_SS tests run (one per candidate of a dispatched pair)
  std::size_t contacts = 0;           ///< btSoftBody::SContacts produced
  std::size_t robust_contacts = 0;    ///< of contacts: made where Bullet's test refuses (Settings::exact Robust/Continuous)
  std::size_t crossing_contacts = 0;  ///< of contacts: nodes that passed through a face this step (Continuous)
  /// Contacts the exact test accepted that Settings::contacts = NearestFace left out (not the
  /// nearest of their node against that body); not in `contacts`. With ExactTest::Bullet the
  /// runaway rule counts them; with Robust the core already left out the candidates beyond each
  /// node's nearest (core.candidates_not_nearest), so only near ties are left out here.
  std::size_t reduced_contacts = 0;
  std::size_t self_bodies = 0;        ///< bodies collided with themselves this step
  std::size_t self_exact_tests = 0;   ///< of exact_tests: a body's nodes against its own faces
  std::size_t self_contacts = 0;      ///< of contacts: a body's nodes against its own faces
  /// Body pairs over the runaway rule (runawayContacts) this step: the bodies are deep inside each
  /// other or faster than the contact radius can follow,
  /// and Bullet's contact response is feeding on itself (each contact pushes its node out to
  /// margin + 2·|Δx|). Contact counts of such pairs grow without bound over the following steps.
  std::size_t runaway_pairs = 0;
  /// Of those, the pairs put on the Ahead bound this step (Settings::runaway_fallback).
  std::size_t runaway_fallbacks = 0;
  /// Body pairs whose contacts beyond the margins shared their weight this step
  /// (Settings::runaway_sharing): the pairs that ran away this step or earlier and have not parted.
  std::size_t sharing_pairs = 0;
  /// Contacts whose m_cfm was divided this step: those of the sharing pairs (their node had more
  /// than one beyond the margins), and in the other pairs those of crowded nodes (more than
  /// Settings::crowded_band beyond the margins).
  std::size_t shared_contacts = 0;
  /// Of shared_contacts, those of crowded nodes in pairs that have not run away.
  std::size_t crowded_contacts = 0;
  /// A warning for the first runaway pair this step, naming the two bodies (their indices in the
  /// world's soft body array) and the contact count; empty when there was none.
  std::string runaway;
  /// Bodies refit right after their btSoftBody::predictMotion (Plugin::afterPredictMotion, which
  /// psc::bullet::SoftBodySolver calls) instead of in the sensor step.
  std::size_t refit_after_predict = 0;
  /// Body synchronisation + SensorWorld::step() + the refits done after predictMotion, wall clock.
  double ms_sensor_step = 0.0;
  double ms_exact = 0.0;              ///< the exact stage, summed over the step's pairs (with the walk for pairs beyond the broadphase), wall clock
  /// Non-empty when the core rejected this step (e.g. a non-finite node position): every pair then
  /// went to Bullet's previous algorithm instead. Never thrown through Bullet's dispatch.
  std::string error;
  /// The core's message for the first participating body it does not hold (see skipped_bodies).
  std::string skipped_reason;
  psc::StepStats core;                ///< the core's own breakdown of the sensor step
};

}  // namespace psc::bullet
