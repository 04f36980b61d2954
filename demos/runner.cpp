#include "runner.h"

#include "bullet_probe.h"
#include "bullet_scene.h"
#include "crossings.h"
#include "ground_truth.h"
#include "psc/error.h"
#include "sensor_pipeline.h"
#include "vtk_writer.h"

#ifdef PSC_DEMO_HAVE_PLUGIN
#include "psc/bullet/stats.h"
#endif

#include <BulletDynamics/Dynamics/btActionInterface.h>
#include <sys/resource.h>
#if defined(__GLIBC__)
#include <malloc.h>
#endif

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <fstream>
#include <functional>
#include <future>
#include <iostream>
#include <limits>
#include <map>
#include <memory>
#include <set>
#include <sstream>
#include <system_error>

namespace psc::demo {
namespace {

using Clock = std::chrono::steady_clock;
double msSince(Clock::time_point t0) { return std::chrono::duration<double, std::milli>(Clock::now() - t0).count(); }

Vec3 toVec(const btVector3& v) { return {v.x(), v.y(), v.z()}; }

/// Positions of every soft body in the form the truth reads (a copy: measurement, not pipeline).
void extractBodies(SceneWorld& sw, std::vector<TruthBody>& out, bool with_prev) {
  const auto& soft = sw.softBodies();
  out.resize(soft.size());
  for (std::size_t i = 0; i < soft.size(); ++i) {
    const btSoftBody* psb = soft[i];
    TruthBody& b = out[i];
    const std::size_t n = static_cast<std::size_t>(psb->m_nodes.size());
    b.x.resize(n);
    b.prev.resize(n);
    for (std::size_t v = 0; v < n; ++v) {
      const auto& node = psb->m_nodes[static_cast<int>(v)];
      b.x[v] = toVec(node.m_x);
      b.prev[v] = with_prev ? toVec(node.m_q) : b.x[v];
    }
    if (b.triangles.empty()) b.triangles = sw.scene().bodies[i].mesh.triangles;
    b.margin = psb->getCollisionShape()->getMargin();
    b.closed = sw.scene().bodies[i].closed;
  }
}

/// Every soft body's node positions (m_x), one vector per body.
void copyPositions(SceneWorld& sw, BodyPositions& out) {
  const auto& soft = sw.softBodies();
  out.resize(soft.size());
  for (std::size_t i = 0; i < soft.size(); ++i) {
    const btSoftBody* psb = soft[i];
    out[i].resize(static_cast<std::size_t>(psb->m_nodes.size()));
    for (int v = 0; v < psb->m_nodes.size(); ++v) out[i][static_cast<std::size_t>(v)] = toVec(psb->m_nodes[v].m_x);
  }
}

/// The body pair (lower index first) of a contact's two bodies.
using BodyPair = std::pair<Index, Index>;

/// The soft-soft contacts Bullet's solver will see this step, as (node body, node, face body, face),
/// sorted and without repeats: those of a body with itself in `self`; those between bodies counted
/// per body pair in `per_pair` and their nodes marked in `had_contact` (per body and node), and
/// kept in `out` only with `keep`. One body's keys at a time go through `scratch`: on a settled
/// fine pile (8 tori × 8,000 vertices, 1.9 million contacts a step) the keys of all bodies at once
/// took 16 bytes a contact (30 MB) and their sort 9% of the run's time, for figures that need only
/// the counts.
std::size_t collectFound(SceneWorld& sw, bool keep, std::vector<ContactKey>& out, std::vector<ContactKey>& self,
                         std::vector<ContactKey>& scratch, std::map<BodyPair, std::size_t>& per_pair,
                         std::vector<std::vector<char>>& had_contact) {
  out.clear();
  self.clear();
  per_pair.clear();
  const auto& soft = sw.softBodies();
  had_contact.resize(soft.size());
  std::size_t found = 0, total = 0;
  for (const btSoftBody* psb : soft) total += static_cast<std::size_t>(psb->m_scontacts.size());
  // Sized before filling (grown by doubling, a list holds up to twice its keys).
  if (keep && total > out.capacity()) {
    out = std::vector<ContactKey>();
    out.reserve(total + total / 8);
  }
  for (std::size_t i = 0; i < soft.size(); ++i) {
    const btSoftBody* psb = soft[i];
    had_contact[i].assign(static_cast<std::size_t>(psb->m_nodes.size()), 0);
    const auto contacts = static_cast<std::size_t>(psb->m_scontacts.size());
    if (contacts > scratch.capacity()) {
      scratch = std::vector<ContactKey>();
      scratch.reserve(contacts + contacts / 8);
    }
    scratch.clear();
    for (int c = 0; c < psb->m_scontacts.size(); ++c) {
      const btSoftBody::SContact& sc = psb->m_scontacts[c];
      const int owner = sw.faceOwner(sc.m_face);
      if (owner < 0) continue;
      const auto node = static_cast<Index>(sc.m_node - &psb->m_nodes[0]);
      const auto face = static_cast<Index>(sc.m_face - &soft[static_cast<std::size_t>(owner)]->m_faces[0]);
      scratch.push_back({static_cast<Index>(i), node, static_cast<Index>(owner), face});
    }
    std::sort(scratch.begin(), scratch.end());
    scratch.erase(std::unique(scratch.begin(), scratch.end()), scratch.end());
    // Sorted by face body first: each other body's keys are one run. Body i's keys come after those
    // of every body before it, so `out` and `self` stay sorted.
    for (std::size_t k = 0; k < scratch.size();) {
      const Index owner = scratch[k].triangle_body;
      std::size_t end = k;
      while (end < scratch.size() && scratch[end].triangle_body == owner) ++end;
      if (owner == static_cast<Index>(i)) {
        self.insert(self.end(), scratch.begin() + static_cast<std::ptrdiff_t>(k), scratch.begin() + static_cast<std::ptrdiff_t>(end));
      } else {
        per_pair[{std::min(owner, static_cast<Index>(i)), std::max(owner, static_cast<Index>(i))}] += end - k;
        found += end - k;
        for (std::size_t j = k; j < end; ++j) had_contact[i][scratch[j].vertex] = 1;
        if (keep) out.insert(out.end(), scratch.begin() + static_cast<std::ptrdiff_t>(k), scratch.begin() + static_cast<std::ptrdiff_t>(end));
      }
      k = end;
    }
  }
  return found;
}

/// The body pairs of `per_pair` over the plugin's runaway rule (psc::bullet::runawayContacts), the
/// same for every pipeline; a warning for the first of them. 0 without the plugin.
std::size_t runawayPairs(SceneWorld& sw, const std::map<BodyPair, std::size_t>& per_pair, std::string& warning) {
#ifdef PSC_DEMO_HAVE_PLUGIN
  std::size_t runaways = 0;
  for (const auto& [pair, contacts] : per_pair) {
    const btSoftBody& a = *sw.softBodies()[pair.first];
    const btSoftBody& b = *sw.softBodies()[pair.second];
    if (!psc::bullet::isRunaway(a, b, contacts)) continue;
    if (++runaways == 1)
      warning = "runaway contact between bodies " + std::to_string(pair.first) + " and " + std::to_string(pair.second) +
                ": " + std::to_string(contacts) + " contacts in one step, over " +
                std::to_string(static_cast<std::size_t>(psc::bullet::runawayContacts(a, b)));
  }
  return runaways;
#else
  (void)sw, (void)per_pair, (void)warning;
  return 0;
#endif
}

double coordinateScale(const std::vector<TruthBody>& bodies) {
  double s = 1.0;
  for (const TruthBody& b : bodies)
    for (const Vec3& p : b.x) s = std::max(s, p.cwiseAbs().maxCoeff());
  return s;
}

bool diverged(SceneWorld& sw, double far_out) {
  for (const btSoftBody* psb : sw.softBodies())
    for (int i = 0; i < psb->m_nodes.size(); ++i) {
      const btVector3& x = psb->m_nodes[i].m_x;
      if (!(std::abs(x.x()) < far_out && std::abs(x.y()) < far_out && std::abs(x.z()) < far_out)) return true;
    }
  return false;
}

/// Calls a function from Bullet's updateActions. Added after the plugin's own action (its end of the
/// dispatch, where it makes the self contacts), it sees every contact of the step, at the same
/// positions (m_x predicted, m_q previous), before the soft-body solve.
class CallAction final : public btActionInterface {
 public:
  explicit CallAction(std::function<void()> f) : f_(std::move(f)) {}
  void updateAction(btCollisionWorld*, btScalar) override { f_(); }
  void debugDraw(btIDebugDraw*) override {}

 private:
  std::function<void()> f_;
};

struct PairKey {
  Index a, b;
  bool operator<(const PairKey& o) const { return a != o.a ? a < o.a : b < o.b; }
};
PairKey pairOf(Index x, Index y) { return {std::min(x, y), std::max(x, y)}; }

}  // namespace

const char* toString(Pipeline p) {
  switch (p) {
    case Pipeline::Sensors: return "sensors";
    case Pipeline::Bounds: return "bounds";
    default: return "bullet";
  }
}
std::string runName(Pipeline p, int bullet_clusters, bool cluster_self_direct) {
  if (p != Pipeline::Bullet || bullet_clusters <= 0) return toString(p);
  return "bullet_cl" + std::to_string(bullet_clusters) + (cluster_self_direct ? "_direct" : "");
}
std::string runName(const RunResult& r) { return runName(r.pipeline, r.bullet_clusters, r.cluster_self_direct); }

const char* toString(FlaggingMode f) { return f == FlaggingMode::Thesis ? "thesis" : "default"; }
const char* toString(TruthMode t) {
  switch (t) {
    case TruthMode::None: return "none";
    case TruthMode::Strict: return "strict";
    case TruthMode::Full: return "full";
    default: return "both";
  }
}

double median(std::vector<double> v) {
  if (v.empty()) return 0.0;
  const std::size_t m = v.size() / 2;
  std::nth_element(v.begin(), v.begin() + static_cast<long>(m), v.end());
  double hi = v[m];
  if (v.size() % 2) return hi;
  const double lo = *std::max_element(v.begin(), v.begin() + static_cast<long>(m));
  return 0.5 * (lo + hi);
}

double mean(const std::vector<double>& v) {
  double s = 0;
  for (double x : v) s += x;
  return v.empty() ? 0.0 : s / double(v.size());
}

void releaseFreedMemory() {
#if defined(__GLIBC__)
  malloc_trim(0);
#endif
}

bool resetPeakRss() {
  std::ofstream f("/proc/self/clear_refs");
  if (!f) return false;
  f << "5";
  f.flush();
  return static_cast<bool>(f);
}

double peakRssMb() {
  std::ifstream status("/proc/self/status");
  std::string line;
  while (std::getline(status, line))
    if (line.rfind("VmHWM:", 0) == 0) {
      std::istringstream in(line.substr(6));
      double kb = 0;
      if (in >> kb) return kb / 1024.0;
    }
  rusage ru{};
  getrusage(RUSAGE_SELF, &ru);
  return static_cast<double>(ru.ru_maxrss) / 1024.0;
}

namespace {

/// What ran, before anything is measured.
RunResult describeRun(const Scene& scene, Pipeline pipeline, const RunOptions& opt) {
  RunResult r;
  r.scene = scene.name;
  if (const SceneInfo* info = findScene(scene.name)) r.scene_number = info->number;
  r.title = scene.title;
  r.scale = scene.scale;
  r.note = scene.note;
  r.pipeline = pipeline;
  if (pipeline == Pipeline::Sensors) r.flagging = toString(opt.flagging);
  if (pipeline == Pipeline::Bounds) r.flagging = "bounds";
  r.exact = pipeline == Pipeline::Bullet ? "bullet" : opt.exact;
  r.motion_bound = pipeline == Pipeline::Bullet ? "" : opt.motion_bound;
  r.runaway_fallback = pipeline != Pipeline::Bullet && opt.runaway_fallback;
  r.runaway_sharing = pipeline != Pipeline::Bullet && opt.runaway_sharing;
  r.crowded_band = pipeline != Pipeline::Bullet ? opt.crowded_band : 0;
  if (pipeline != Pipeline::Bullet) r.contacts = opt.contacts;
  if (pipeline == Pipeline::Bullet && opt.bullet_clusters > 0) {
    r.bullet_clusters = opt.bullet_clusters;
    r.cluster_self_direct = opt.cluster_self_direct;
  }
  r.self_collision = (pipeline != Pipeline::Bullet && opt.self_collision) || r.bullet_clusters > 0;
  r.self_rest_bound = pipeline != Pipeline::Bullet && opt.self_collision && opt.self_rest_bound;
  r.bodies = scene.bodies.size();
  r.resolution = scene.resolution();
  r.steps = opt.steps ? opt.steps : scene.default_steps;
  for (const SoftBodySpec& b : scene.bodies) r.vertices += b.mesh.vertices.size();
  r.has_strict = opt.truth == TruthMode::Strict || opt.truth == TruthMode::Both;
  r.has_full = opt.truth == TruthMode::Full || opt.truth == TruthMode::Both;
  r.has_sensor_figures = pipeline != Pipeline::Bullet;
  r.has_self_truth = opt.self_collision && r.has_strict;
  r.warmup = opt.warmup ? std::min(opt.warmup, r.steps - 1)
                        : std::min<std::size_t>(10, std::max<std::size_t>(1, r.steps / 10));
  return r;
}

psc::Flagging coreFlagging(Pipeline pipeline, FlaggingMode mode) {
  if (pipeline == Pipeline::Bounds) return psc::Flagging::Bounds;
  return mode == FlaggingMode::Thesis ? psc::Flagging::Sensors : psc::Flagging::SensorsAndBounds;
}

/// One run in progress: the Bullet world with its pipeline, the instruments inside its step, the
/// ground truth, and the frame series. Each step fills one StepRecord.
class Run {
 public:
  Run(const Scene& scene, Pipeline pipeline, const RunOptions& opt, bool strict, bool full);
  ~Run() { world_.world().removeAction(&after_actions_); }
  Run(const Run&) = delete;
  Run& operator=(const Run&) = delete;

  /// Steps the world once and fills `rec`: the step's times, and (from the hook after collision
  /// detection) the contacts found and their comparison with the truth.
  void step(StepRecord& rec);
  /// A node position non-finite or 1000 scene extents out.
  bool diverged();
  /// After the step: edge–triangle crossings between bodies and within each body, the vertices
  /// that passed through another body's triangle during it without a soft-soft contact, and with
  /// `penetration` the vertices inside another closed body beyond the margins. On two threads.
  void measureAfterStep(StepRecord& rec, bool penetration);
  void writeFrame(std::size_t step);
  bool writesFrame(std::size_t step) const {
    return frames_ && step % std::max<std::size_t>(1, opt_.frame_every) == 0;
  }
  void finish() {
    if (frames_) frames_->finish();
  }
  double midphaseBytesPerVertex(std::size_t vertices);

 private:
  void compareWithTruth(StepRecord& rec);
  /// After the plugin's action: positions are still m_x (predicted) and m_q (previous), exactly
  /// what CollideVF_SS used, and m_scontacts holds every contact of the step. Records the found
  /// contacts (between bodies and self), the runaway rule, Bullet's exact tests, and their
  /// comparison with the truths.
  void afterActions();
  void compareWithSelfTruth(StepRecord& rec);
  /// Triangles CollideVF_SS refuses outright (|cross|² ≤ SIMD_EPSILON), on bodies_ as last extracted.
  bool untestable(const ContactKey& k) const;

  const Scene& scene_;
  Pipeline pipeline_;
  const RunOptions& opt_;
  SceneWorld world_;
  std::unique_ptr<SensorPipeline> sensors_;
  CallAction after_actions_{[this] { afterActions(); }};
  ZoneTimer zone_{"Deformable Collision"};
  TruthSettings truth_settings_;
  GroundTruth truth_;
  const TruthResult* last_truth_ = nullptr;
  TriangleGrid pen_grid_;
  std::vector<TruthBody> bodies_;
  /// This step's contacts (collectFound): between bodies (kept only for the truths and the frames)
  /// and of a body with itself; the contacts between bodies per body pair.
  std::vector<ContactKey> found_, found_self_, found_scratch_;
  std::map<BodyPair, std::size_t> found_per_pair_;
  /// The self truth's rest shapes: the scene's initial mesh of each body, which is what the plugin
  /// takes at its first step (its m_x then: the initial positions moved by one step, all nodes alike).
  SelfRule self_rule_;  ///< with --self-collision: the scene's initial meshes as rest shapes
  std::set<PairKey> truth_pairs_, found_pairs_;
  std::vector<CrossingMesh> crossing_meshes_;  ///< body i = scene.bodies[i]'s triangles
  CrossingCounter crossings_;
  CrossingCounter self_crossings_;  ///< its own buffers: it counts on a second thread (measureAfterStep)
  /// Node positions before the step, copied before stepSimulation: m_q is the step's start only
  /// until Bullet's drift solve (diterations > 0) overwrites it.
  BodyPositions before_, after_;
  /// after_ holds the positions as they are now: copied by measureAfterStep, and nothing moves a
  /// node between it and the next step, which then takes it as before_ instead of copying again.
  bool after_current_ = false;
  std::vector<std::vector<char>> had_contact_;  ///< per body and node: in a contact with another body this step
  std::unique_ptr<FrameSeries> frames_;
  double far_out_ = 1.0;             ///< far enough out to mean the simulation blew up
  StepRecord* current_ = nullptr;    ///< the record of the step under way
  std::size_t steps_begun_ = 0;      ///< steps begun in this run (warm-up included)
  bool runaway_told_ = false;        ///< the first runaway was written to stderr as it happened
  Clock::time_point detect_start_;
  std::size_t joints_before_detect_ = 0;  ///< cluster contacts of the last self pass, not yet solved
};

WorldOptions worldOptions(Pipeline pipeline, const RunOptions& opt) {
  WorldOptions wo;
  if (pipeline != Pipeline::Bullet) {
    if (!SensorPipeline::available())
      throw Error(ErrorCode::InvalidArgument, "this psc_demo was built without psc::bullet: use --pipeline bullet");
    wo.soft_collision_flags = SensorPipeline::bodyCollisionFlags();
  } else if (opt.bullet_clusters > 0) {
    // Bullet's cluster collision instead of VF_SS. As documented: CL_SS | CL_SELF. Bullet 3.24's
    // defaultCollisionHandler switches on (flags & SVSmask) with SVSmask = 0xf0, which holds CL_SELF,
    // so no case matches: no cluster contact at all. Direct: CL_SS alone (clusters between bodies
    // through Bullet) and the self pass calls what the CL_SS case would call for CL_SELF.
    using F = btSoftBody::fCollision;
    wo.soft_collision_flags = F::SDF_RS | F::CL_SS | (opt.cluster_self_direct ? 0 : F::CL_SELF);
    wo.clusters = opt.bullet_clusters;
    wo.call_cluster_self = opt.cluster_self_direct;
  }
  return wo;
}

Run::Run(const Scene& scene, Pipeline pipeline, const RunOptions& opt, bool strict, bool full)
    : scene_(scene), pipeline_(pipeline), opt_(opt), world_(scene, worldOptions(pipeline, opt)) {
  if (pipeline != Pipeline::Bullet) {
    SensorPipeline::Options o;
    o.flagging = coreFlagging(pipeline, opt.flagging);
    o.exact = opt.exact;
    o.motion_bound = opt.motion_bound;
    o.contacts = opt.contacts;
    o.self_collision = opt.self_collision;
    o.self_rest_bound = opt.self_rest_bound;
    o.refit_after_predict = opt.refit_after_predict;
    o.runaway_fallback = opt.runaway_fallback;
    o.runaway_sharing = opt.runaway_sharing;
    o.crowded_band = opt.crowded_band;
    sensors_ = std::make_unique<SensorPipeline>(world_, o);
  }
  truth_settings_.strict = strict;
  truth_settings_.full = full;
  world_.world().before_collision = [this] {
    zone_.arm(true);
    joints_before_detect_ = jointCount(world_.softBodies());
    detect_start_ = Clock::now();
  };
  world_.world().addAction(&after_actions_);  // after the plugin's
  world_.world().after_collision = [this] {
    zone_.arm(false);
    current_->ms.detect = msSince(detect_start_);
    const auto h0 = Clock::now();
    current_->n.cluster_contacts = jointCount(world_.softBodies()) - joints_before_detect_;
    current_->ms.hooks += msSince(h0);
  };
  for (const SoftBodySpec& b : scene.bodies)
    for (const Vec3& v : b.mesh.vertices) far_out_ = std::max(far_out_, v.cwiseAbs().maxCoeff());
  far_out_ *= 1000.0;
  for (const SoftBodySpec& b : scene.bodies) crossing_meshes_.push_back(crossingMesh(b.mesh.triangles));
  if (opt.self_collision) {
    std::vector<std::vector<Triangle>> triangles;
    std::vector<std::vector<Vec3>> rest;
    for (const SoftBodySpec& b : scene.bodies) triangles.push_back(b.mesh.triangles), rest.push_back(b.mesh.vertices);
    self_rule_ = selfRule(triangles, std::move(rest));
  }
  if (!opt.frames_dir.empty()) {
    frames_ = std::make_unique<FrameSeries>(
        opt.frames_dir, opt.frames_name.empty()
                             ? scene.name + "_" + runName(pipeline, opt.bullet_clusters, opt.cluster_self_direct)
                             : opt.frames_name);
    std::vector<std::pair<Vec3, Vec3>> boxes;
    for (const StaticBoxSpec& b : scene.statics) boxes.emplace_back(b.center, b.half_extents);
    frames_->writeStatic(boxes);
  }
}

void Run::step(StepRecord& rec) {
  current_ = &rec;
  ++steps_begun_;
  const auto c0 = Clock::now();
  if (after_current_) before_.swap(after_);
  else copyPositions(world_, before_);
  after_current_ = false;
  rec.ms.crossings = msSince(c0);
  const auto t0 = Clock::now();
  world_.step();
  rec.ms.step = msSince(t0) - rec.ms.hooks;
  rec.ms.hooks += rec.ms.crossings;  // the copy, outside stepSimulation
  rec.ms.face_refit = world_.softSolver().lastFaceRefitMs();
  rec.ms.traversal_exact = zone_.takeMs();  // ours: pairs handed back to Bullet
  zone_.takeCount();
  if (opt_.bullet_clusters > 0 && pipeline_ == Pipeline::Bullet) {
    rec.ms.cluster_self = world_.softSolver().lastSelfPassMs();
    rec.n.self_cluster_contacts = world_.softSolver().lastSelfClusterContacts();
  }
  if (sensors_) sensors_->takeStep(rec);
  current_ = nullptr;
}

void Run::afterActions() {
  const auto h0 = Clock::now();
  // Every contact of the step is made by now: the plugin's action (before this one) collides the
  // pairs Bullet's broadphase did not dispatch (Settings::beyond_broadphase) and the self pairs.
  // Taken at the end of the dispatch instead, the found contacts missed the first: a fast body
  // within its contact radius of another, but with boxes apart, counted as found nothing
  // (projectile at 1,000 vertices: full recall 0.175 where it is 0.998).
  // The keys themselves only for what compares them: the truths and the frames.
  const bool keep = opt_.truth != TruthMode::None || frames_ != nullptr;
  current_->n.contacts_found = collectFound(world_, keep, found_, found_self_, found_scratch_, found_per_pair_, had_contact_);
  current_->n.runaway_pairs = runawayPairs(world_, found_per_pair_, current_->runaway);
  if (current_->n.runaway_pairs > 0 && !runaway_told_) {
    // Told as it happens, not only in the run's summary: a runaway's contacts can fill the memory
    // long before the run ends.
    runaway_told_ = true;
    std::cerr << "psc_demo: RUNAWAY in " << scene_.name << " (" << runName(pipeline_, opt_.bullet_clusters, opt_.cluster_self_direct)
              << ") at step " << steps_begun_ << ": " << current_->runaway
              << "; the run goes on (docs/BENCHMARK.md, \"Runaways\")" << std::endl;
  }
  if (pipeline_ == Pipeline::Bullet) current_->n.exact_tests = countVFExactTests(world_.world());
  if (opt_.truth != TruthMode::None) compareWithTruth(*current_);
  current_->n.self_contacts_found = found_self_.size();
  if (opt_.self_collision && opt_.truth != TruthMode::None && truth_settings_.strict) compareWithSelfTruth(*current_);
  current_->ms.hooks += msSince(h0);
}

bool Run::untestable(const ContactKey& k) const {
  const TruthBody& tb = bodies_[k.triangle_body];
  const Triangle& t = tb.triangles[k.triangle];
  return (tb.x[t[1]] - tb.x[t[0]]).cross(tb.x[t[2]] - tb.x[t[0]]).squaredNorm() <= double(SIMD_EPSILON);
}

void Run::compareWithSelfTruth(StepRecord& rec) {
  // bodies_ and the band are this step's, from compareWithTruth.
  const auto t0 = Clock::now();
  const TruthResult& tr = truth_.computeSelf(bodies_, self_rule_, truth_settings_);
  rec.ms.truth += msSince(t0);
  StepCounts& n = rec.n;
  for (const ContactKey& k : found_self_) {
    const TruthContact* c = tr.find(k);
    if (c && c->strict == Membership::Inside) {
      ++n.self_found_in_strict_all;
      if (!untestable(k)) ++n.self_found_in_strict;
    }
    if (truth_settings_.full && (!c || c->full == Membership::Outside)) ++n.self_outside_truth;
  }
  for (const TruthContact& c : tr.contacts) {
    if (c.strict != Membership::Inside) continue;
    ++n.self_truth_strict_all;
    if (!untestable(c.key)) ++n.self_truth_strict;
  }
}

void Run::compareWithTruth(StepRecord& rec) {
  // Bullet decides in btScalar: a pair this close to the radius may go either way on rounding.
  const double scalar_eps = std::numeric_limits<btScalar>::epsilon();
  const bool full = truth_settings_.full;
  const auto t0 = Clock::now();
  extractBodies(world_, bodies_, true);
  truth_settings_.band_absolute = 16.0 * scalar_eps * coordinateScale(bodies_);
  const TruthResult& tr = truth_.compute(bodies_, truth_settings_);
  last_truth_ = &tr;
  rec.ms.truth = msSince(t0);
  StepCounts& n = rec.n;
  found_pairs_.clear();
  for (const ContactKey& k : found_) {
    found_pairs_.insert(pairOf(k.vertex_body, k.triangle_body));
    const TruthContact* c = tr.find(k);
    if (c && c->strict == Membership::Inside) {
      ++n.found_in_strict;
      n.found_in_strict_untestable += untestable(k);  // Robust and Continuous find these too
    }
    if (c && c->full == Membership::Inside) ++n.found_in_full;
    if (full && (!c || c->full == Membership::Outside)) ++n.outside_truth;
  }
  truth_pairs_.clear();
  for (const TruthContact& c : tr.contacts) {
    if (c.strict == Membership::Inside) n.truth_strict_untestable += untestable(c.key);
    const Membership widest = full ? c.full : c.strict;
    if (widest == Membership::Inside) truth_pairs_.insert(pairOf(c.key.vertex_body, c.key.triangle_body));
    n.truth_ambiguous += (c.strict == Membership::Ambiguous || c.full == Membership::Ambiguous);
  }
  for (const PairKey& p : truth_pairs_) n.truth_pairs_found += found_pairs_.count(p);
  n.truth_pairs = truth_pairs_.size();
  n.truth_strict = tr.strict_inside;
  n.truth_full = tr.full_inside;
}

bool Run::diverged() { return psc::demo::diverged(world_, far_out_); }

void Run::measureAfterStep(StepRecord& rec, bool penetration) {
  const auto t0 = Clock::now();
  copyPositions(world_, after_);
  // Two threads share the counts. A second one measures the penetration, then takes the bodies'
  // self counts one by one, while this one counts the crossings between bodies and the tunnelled
  // vertices, then helps with the self counts left. This is measurement between steps, outside
  // every timed section: the pipelines' timed parts stay single-threaded, and the sums are the
  // same whoever counts which body. Each thread writes only its own buffers (the second bodies_,
  // pen_grid_ and self_crossings_; this one crossings_), and both read the world and the copies.
  std::atomic<std::size_t> next_body{0};
  const auto selfCounts = [this, &next_body](CrossingCounter& counter) {
    std::size_t count = 0;
    for (std::size_t b; (b = next_body.fetch_add(1)) < crossing_meshes_.size();)
      count += counter.selfEdgeCrossings(crossing_meshes_, after_, b);
    return count;
  };
  Penetration pen;
  const auto second = [&] {
    if (penetration) {
      extractBodies(world_, bodies_, false);
      pen = psc::demo::measurePenetration(bodies_, pen_grid_);
    }
    return selfCounts(self_crossings_);
  };
  std::future<std::size_t> helper;
  try {
    helper = std::async(std::launch::async, second);
  } catch (const std::system_error&) {
    // No thread to be had: this thread does it all.
  }
  rec.n.edge_crossings = crossings_.edgeCrossings(crossing_meshes_, after_);
  rec.n.tunnelled_vertices =
      crossings_.tunnelledVertices(crossing_meshes_, before_, after_, had_contact_, &rec.n.passed_vertices);
  rec.n.self_edge_crossings = selfCounts(crossings_);
  rec.n.self_edge_crossings += helper.valid() ? helper.get() : second();
  after_current_ = true;
  if (penetration) {
    rec.n.penetrating_vertices = pen.vertices;
    if (pen.vertices) rec.max_penetration = pen.max_depth;
  }
  const double took = msSince(t0);
  rec.ms.crossings += took;
  rec.ms.hooks += took;
}

void Run::writeFrame(std::size_t step) {
  extractBodies(world_, bodies_, false);
  std::vector<FrameBody> fb(bodies_.size());
  SensorView view;
  if (sensors_) view = sensors_->view();
  for (std::size_t b = 0; b < bodies_.size(); ++b) {
    fb[b].x = bodies_[b].x;
    fb[b].triangles = &bodies_[b].triangles;
    fb[b].contact.assign(bodies_[b].x.size(), 0);
    fb[b].self_contact.assign(bodies_[b].x.size(), 0);
    fb[b].missed.assign(bodies_[b].x.size(), 0);
    if (sensors_ && b < view.region_of.size() && !view.region_of[b].empty()) {
      fb[b].region = view.region_of[b];
      fb[b].flagged.assign(bodies_[b].x.size(), 0);
      for (std::size_t v = 0; v < fb[b].region.size(); ++v) {
        const auto reg = static_cast<std::size_t>(fb[b].region[v]);
        fb[b].flagged[v] = reg < view.region_flagged[b].size() ? view.region_flagged[b][reg] : 0;
      }
    }
  }
  const auto markTriangle = [&](std::vector<char> FrameBody::*member, Index body, Index tri) {
    for (Index v : bodies_[body].triangles[tri]) (fb[body].*member)[v] = 1;
  };
  for (const ContactKey& k : found_) {
    fb[k.vertex_body].contact[k.vertex] = 1;
    markTriangle(&FrameBody::contact, k.triangle_body, k.triangle);
  }
  for (const ContactKey& k : found_self_) {
    fb[k.vertex_body].contact[k.vertex] = 1;
    fb[k.vertex_body].self_contact[k.vertex] = 1;
    markTriangle(&FrameBody::contact, k.triangle_body, k.triangle);
    markTriangle(&FrameBody::self_contact, k.triangle_body, k.triangle);
  }
  if (last_truth_) {
    // Truth contacts of this step's collision pass (strict if asked, else full) not found.
    for (const TruthContact& c : last_truth_->contacts) {
      const Membership m = truth_settings_.strict ? c.strict : c.full;
      if (m != Membership::Inside || std::binary_search(found_.begin(), found_.end(), c.key)) continue;
      fb[c.key.vertex_body].missed[c.key.vertex] = 1;
      markTriangle(&FrameBody::missed, c.key.triangle_body, c.key.triangle);
    }
  }
  if (!sensors_)
    for (std::size_t b = 0; b < fb.size(); ++b) fb[b].flagged = fb[b].contact;
  std::vector<FrameParticle> parts;
  for (const auto& p : view.particles) {
    FrameParticle fp;
    fp.x = bodies_[p.body].x[p.vertex];
    fp.body = static_cast<int>(p.body);
    fp.region = static_cast<int>(p.region);
    fp.flagged = p.region < view.region_flagged[p.body].size() && view.region_flagged[p.body][p.region];
    parts.push_back(fp);
  }
  frames_->writeFrame(step, static_cast<double>(step + 1) * scene_.dt, fb, parts);
}

double Run::midphaseBytesPerVertex(std::size_t vertices) {
  if (sensors_) return sensors_->midphaseBytesPerVertex();
  std::size_t bytes = 0;
  for (btSoftBody* b : world_.softBodies()) bytes += bulletMidphaseBytes(*b);
  return vertices ? double(bytes) / double(vertices) : 0.0;
}

/// Counts over every step run, recall over them, and the worst step.
void summariseCounts(RunResult& r) {
  double worst_strict = 1.0, worst_full = 1.0;
  std::size_t exact_total = 0, flagged_total = 0;
  long rounds_total = 0;
  r.core_counts_per_step.assign(coreCounters().size(), 0.0);
  for (const StepRecord& rec : r.per_step) {
    const StepCounts& n = rec.n;
    for (std::size_t k = 0; k < coreCounters().size(); ++k)
      r.core_counts_per_step[k] += static_cast<double>(rec.core.*coreCounters()[k].second);
    r.contacts_found_total += n.contacts_found;
    r.reduced_contacts_total += n.reduced_contacts;
    exact_total += n.exact_tests;
    flagged_total += n.flagged_pairs;
    rounds_total += n.rounds;
    r.particles = std::max(r.particles, n.particles);
    r.round_cap_hits += n.round_cap_hits;
    r.repartitions += n.repartitions;
    r.fallback_pairs += n.fallback_pairs;
    r.sharing_steps += n.sharing_pairs > 0 ? 1 : 0;
    r.shared_contacts += n.shared_contacts;
    r.crowded_contacts += n.crowded_contacts;
    if (r.pipeline_error.empty() && !rec.error.empty()) r.pipeline_error = rec.error;
    r.truth_strict_total += n.truth_strict;
    r.truth_full_total += n.truth_full;
    r.found_in_strict += n.found_in_strict;
    r.found_in_full += n.found_in_full;
    r.contacts_outside_truth += n.outside_truth;
    r.truth_pairs_total += n.truth_pairs;
    r.truth_pairs_found += n.truth_pairs_found;
    r.truth_ambiguous += n.truth_ambiguous;
    r.truth_strict_untestable += n.truth_strict_untestable;
    r.found_in_strict_untestable += n.found_in_strict_untestable;
    r.truth_seconds += rec.ms.truth / 1000.0;
    if (n.truth_strict) worst_strict = std::min(worst_strict, double(n.found_in_strict) / double(n.truth_strict));
    if (n.truth_full) worst_full = std::min(worst_full, double(n.found_in_full) / double(n.truth_full));
    if (n.penetrating_vertices) {
      ++r.penetration_steps;
      r.max_penetration = std::max(r.max_penetration, rec.max_penetration);
    }
    if (n.runaway_pairs && r.runaway_steps++ == 0)
      r.runaway_warning = "step " + std::to_string(&rec - r.per_step.data() + 1) + ": " + rec.runaway;
    r.intersections_max = std::max(r.intersections_max, n.edge_crossings);
    r.intersections_steps += n.edge_crossings > 0;
    r.self_intersections_max = std::max(r.self_intersections_max, n.self_edge_crossings);
    r.self_intersections_steps += n.self_edge_crossings > 0;
    r.self_contacts_found_total += n.self_contacts_found;
    r.self_truth_strict_total += n.self_truth_strict;
    r.self_found_in_strict += n.self_found_in_strict;
    r.self_truth_strict_all_total += n.self_truth_strict_all;
    r.self_found_in_strict_all += n.self_found_in_strict_all;
    r.self_contacts_outside_truth += n.self_outside_truth;
    r.tunnelled_total += n.tunnelled_vertices;
    r.tunnelled_worst_step = std::max(r.tunnelled_worst_step, n.tunnelled_vertices);
    r.passed_total += n.passed_vertices;
    r.passed_worst_step = std::max(r.passed_worst_step, n.passed_vertices);
    r.cluster_contacts_total += n.cluster_contacts;
    r.self_cluster_contacts_total += n.self_cluster_contacts;
  }
  const double steps = static_cast<double>(r.steps);
  // Over an empty truth a recall is 1 (no true contact was lost) in the JSON, beside the truth's
  // size; the table prints "none" there, so that a run with nothing to find never reads as one that
  // found everything (printTable).
  const auto recall = [](std::size_t found, std::size_t truth) { return truth ? double(found) / double(truth) : 1.0; };
  r.recall_strict = recall(r.found_in_strict, r.truth_strict_total);
  r.recall_full = recall(r.found_in_full, r.truth_full_total);
  r.recall_strict_worst_step = worst_strict;
  r.recall_strict_testable = recall(r.found_in_strict - r.found_in_strict_untestable,
                                    r.truth_strict_total - r.truth_strict_untestable);
  r.recall_full_worst_step = worst_full;
  r.self_recall_strict = recall(r.self_found_in_strict, r.self_truth_strict_total);
  r.self_recall_strict_all = recall(r.self_found_in_strict_all, r.self_truth_strict_all_total);
  r.pair_recall = recall(r.truth_pairs_found, r.truth_pairs_total);
  r.exact_tests_per_step = double(exact_total) / steps;
  r.flagged_pairs_per_step = double(flagged_total) / steps;
  r.rounds_per_step = double(rounds_total) / steps;
  for (double& c : r.core_counts_per_step) c /= steps;
}

/// Times over the timed steps (after the warm-up): means, medians, maxima, and the collision
/// median over the timed steps that found a contact.
void summariseTimes(RunResult& r) {
  static constexpr double StepTimes::*kParts[] = {
      &StepTimes::step,        &StepTimes::hooks,    &StepTimes::truth,      &StepTimes::crossings,
      &StepTimes::detect,
      &StepTimes::face_refit,  &StepTimes::traversal_exact, &StepTimes::cluster_self,
      &StepTimes::sensor_step, &StepTimes::exact,
      &StepTimes::particle,    &StepTimes::refit,    &StepTimes::flagging,   &StepTimes::candidates,
      &StepTimes::repartition, &StepTimes::core_total};
  const std::size_t first = std::min(r.warmup, r.per_step.size());
  r.timed_steps = r.per_step.size() - first;
  std::vector<double> collision, collision_contact, part;
  for (std::size_t i = first; i < r.per_step.size(); ++i) {
    collision.push_back(r.per_step[i].ms.collision());
    if (r.per_step[i].n.contacts_found) collision_contact.push_back(collision.back());
    r.collision_ms_max = std::max(r.collision_ms_max, collision.back());
    r.step_ms_max = std::max(r.step_ms_max, r.per_step[i].ms.step);
  }
  for (double StepTimes::*member : kParts) {
    part.clear();
    for (std::size_t i = first; i < r.per_step.size(); ++i) part.push_back(r.per_step[i].ms.*member);
    r.stage_ms_mean.*member = mean(part);
    r.stage_ms_median.*member = median(part);
  }
  r.collision_ms_mean = mean(collision);
  r.collision_ms_median = median(collision);
  r.collision_ms_contact_median = median(collision_contact);
  r.contact_steps_timed = collision_contact.size();
  r.step_ms_mean = r.stage_ms_mean.step;
  r.step_ms_median = r.stage_ms_median.step;
}

}  // namespace

RunResult runPipeline(const Scene& scene, Pipeline pipeline, const RunOptions& opt) {
  const auto run_start = Clock::now();
  RunResult r = describeRun(scene, pipeline, opt);
  releaseFreedMemory();
  resetPeakRss();
  Run run(scene, pipeline, opt, r.has_strict, r.has_full);
  r.per_step.reserve(r.steps);
  for (std::size_t step = 0; step < r.steps; ++step) {
    r.per_step.emplace_back();
    StepRecord& rec = r.per_step.back();
    run.step(rec);
    if (run.diverged()) {
      r.diverged_at_step = static_cast<long>(step);
      r.steps = step + 1;
      break;
    }
    run.measureAfterStep(rec, opt.penetration);
    if (run.writesFrame(step)) run.writeFrame(step);
    if (step + 1 == RunResult::kEarlySteps) r.peak_rss_mb_early = peakRssMb();
  }
  run.finish();
  summariseCounts(r);
  summariseTimes(r);
  r.midphase_bytes_per_vertex = run.midphaseBytesPerVertex(r.vertices);
  r.peak_rss_mb = peakRssMb();
  if (r.steps < RunResult::kEarlySteps) r.peak_rss_mb_early = r.peak_rss_mb;
  r.wall_seconds = msSince(run_start) / 1000.0;
  return r;
}

}  // namespace psc::demo
