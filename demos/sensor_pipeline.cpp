#include "sensor_pipeline.h"

#include "psc/error.h"

#ifdef PSC_DEMO_HAVE_PLUGIN
#include "psc/bullet/bullet.h"
#endif

namespace psc::demo {

#ifdef PSC_DEMO_HAVE_PLUGIN

struct SensorPipeline::Impl {
  // Built from install()'s result: psc::bullet::Plugin's inline default constructor does not
  // compile outside the plugin (its Installation is incomplete here).
  Impl(SceneWorld& w, psc::bullet::Plugin p) : world(&w), plugin(std::move(p)) {}
  SceneWorld* world;
  psc::bullet::Plugin plugin;
  std::uint64_t last_sensor_steps = 0;
};

bool SensorPipeline::available() { return true; }

int SensorPipeline::bodyCollisionFlags() { return btSoftBody::fCollision::SDF_RS; }

SensorPipeline::SensorPipeline(SceneWorld& world, const Options& options) {
  psc::bullet::Settings settings;
  settings.opt_in = psc::bullet::OptIn::Explicit;
  settings.sensors.flagging = options.flagging;
  settings.self_collision = options.self_collision;
  settings.sensors.self_rest_bound = options.self_rest_bound;
  settings.runaway_fallback = options.runaway_fallback;
  settings.runaway_sharing = options.runaway_sharing;
  settings.crowded_band = options.crowded_band;
  settings.exact = psc::bullet::exactTestFromString(options.exact);
  if (options.motion_bound == "radius") settings.sensors.motion_bound = psc::MotionBound::Radius;
  else if (options.motion_bound == "ahead") settings.sensors.motion_bound = psc::MotionBound::Ahead;
  else if (options.motion_bound == "swept") settings.sensors.motion_bound = psc::MotionBound::Swept;
  else throw psc::Error(psc::ErrorCode::InvalidArgument, "motion bound '" + options.motion_bound + "' is not one of radius, ahead, swept");
  if (options.contacts == "all") settings.contacts = psc::bullet::ContactSet::AllPairs;
  else if (options.contacts == "nearest") settings.contacts = psc::bullet::ContactSet::NearestFace;
  else throw psc::Error(psc::ErrorCode::InvalidArgument, "contact set '" + options.contacts + "' is not one of all, nearest");
  impl_ = std::make_shared<Impl>(world, psc::bullet::install(world.world(), settings));
  for (btSoftBody* body : world.softBodies()) impl_->plugin.setEnabled(body, true);
  if (options.refit_after_predict) {
    psc::bullet::Plugin* plugin = &impl_->plugin;  // Impl is not moved: the world holds it until its end
    world.softSolver().setAfterPredict([plugin](const btSoftBody& body) { plugin->afterPredictMotion(body); });
  }
  // The world destroys its attachments before its bodies and itself: the plugin must go first.
  world.attach(impl_);
}

SensorPipeline::~SensorPipeline() = default;

void SensorPipeline::takeStep(StepRecord& record) {
  const psc::bullet::Stats& s = impl_->plugin.stats();
  record.n.fallback_pairs = s.fallback_pairs;
  if (s.sensor_steps == impl_->last_sensor_steps) return;  // no soft-soft pair this step
  impl_->last_sensor_steps = s.sensor_steps;
  StepCounts& n = record.n;
  n.sensed = true;
  n.particles = s.particles;
  n.rounds = s.rounds;
  n.round_cap_hits = s.round_cap_hits;
  n.flagged_pairs = s.flagged_pairs;
  n.candidate_pairs = s.candidate_pairs;
  n.exact_tests = s.exact_tests;
  n.reduced_contacts = s.reduced_contacts;
  n.sharing_pairs = s.sharing_pairs;
  n.shared_contacts = s.shared_contacts;
  n.crowded_contacts = s.crowded_contacts;
  // The plugin's runaway rule counts what its exact test accepted, before a contact reduction:
  // with --contacts nearest the contacts found stay under the rule while a runaway goes on.
  if (s.runaway_pairs > n.runaway_pairs) {
    n.runaway_pairs = s.runaway_pairs;
    record.runaway = s.runaway;
  }
  n.repartitions = s.repartitions;
  StepTimes& ms = record.ms;
  ms.sensor_step = s.ms_sensor_step;
  ms.exact = s.ms_exact;
  ms.particle = s.core.ms_sensors;
  ms.refit = s.core.ms_refit;
  ms.flagging = s.core.ms_flagging;
  ms.candidates = s.core.ms_candidates;
  ms.repartition = s.core.ms_repartition;
  ms.core_total = s.core.ms_total;
  record.core = s.core;
  record.error = s.error.empty() ? s.skipped_reason : s.error;
}

double SensorPipeline::midphaseBytesPerVertex() const {
  std::size_t bytes = 0, vertices = 0;
  for (btSoftBody* body : impl_->world->softBodies()) {
    vertices += static_cast<std::size_t>(body->m_nodes.size());
    if (auto id = impl_->plugin.bodyId(body)) bytes += impl_->plugin.sensorWorld().memoryBytes(*id);
  }
  return vertices ? static_cast<double>(bytes) / static_cast<double>(vertices) : 0.0;
}

SensorView SensorPipeline::view() const {
  SensorView v;
  const auto& bodies = impl_->world->softBodies();
  const psc::SensorWorld& sw = impl_->plugin.sensorWorld();
  v.region_of.resize(bodies.size());
  v.region_flagged.resize(bodies.size());
  std::vector<std::pair<psc::BodyId, std::size_t>> index;  // sensor id -> scene body
  for (std::size_t i = 0; i < bodies.size(); ++i) {
    const auto id = impl_->plugin.bodyId(bodies[i]);
    if (!id) continue;
    index.emplace_back(*id, i);
    try {
      const psc::Partition& p = sw.partition(*id);
      v.region_of[i].assign(p.region_of.begin(), p.region_of.end());
      v.region_flagged[i].assign(p.regionCount(), 0);
    } catch (const psc::Error&) {
      // not partitioned yet (no soft-soft pair dispatched so far)
    }
  }
  const auto scene_body = [&](psc::BodyId id) -> long {
    for (const auto& [sid, i] : index)
      if (sid == id) return static_cast<long>(i);
    return -1;
  };
  for (const psc::ParticleState& p : sw.particles()) {
    const long i = scene_body(p.body);
    if (i >= 0) v.particles.push_back({static_cast<std::size_t>(i), p.vertex, p.region});
  }
  const auto mark = [&](psc::BodyId id, Index region) {
    const long i = scene_body(id);
    if (i >= 0 && region < v.region_flagged[static_cast<std::size_t>(i)].size())
      v.region_flagged[static_cast<std::size_t>(i)][region] = 1;
  };
  for (const psc::FlaggedPair& f : sw.lastResult().flagged) {
    mark(f.body_a, f.region_a);
    mark(f.body_b, f.region_b);
  }
  return v;
}

#else  // no plugin

struct SensorPipeline::Impl {};
bool SensorPipeline::available() { return false; }
int SensorPipeline::bodyCollisionFlags() { return btSoftBody::fCollision::SDF_RS; }
SensorPipeline::SensorPipeline(SceneWorld&, psc::Flagging, const std::string&, const std::string&, bool, bool, bool) {
  throw Error(ErrorCode::InvalidArgument, "this psc_demo was built without psc::bullet: use --pipeline bullet");
}
SensorPipeline::~SensorPipeline() = default;
void SensorPipeline::takeStep(StepRecord&) {}
double SensorPipeline::midphaseBytesPerVertex() const { return 0.0; }
SensorView SensorPipeline::view() const { return {}; }

#endif

}  // namespace psc::demo
