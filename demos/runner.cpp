#include "runner.h"

#include "bullet_probe.h"
#include "bullet_scene.h"
#include "ground_truth.h"
#include "psc/error.h"
#include "sensor_pipeline.h"
#include "vtk_writer.h"

#include <sys/resource.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <fstream>
#include <limits>
#include <memory>
#include <set>
#include <sstream>

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

/// The soft-soft contacts Bullet's solver will see this step, as (node body, node, face body, face).
void collectFound(SceneWorld& sw, std::vector<ContactKey>& out) {
  out.clear();
  const auto& soft = sw.softBodies();
  for (std::size_t i = 0; i < soft.size(); ++i) {
    const btSoftBody* psb = soft[i];
    for (int c = 0; c < psb->m_scontacts.size(); ++c) {
      const btSoftBody::SContact& sc = psb->m_scontacts[c];
      const int owner = sw.faceOwner(sc.m_face);
      if (owner < 0 || static_cast<std::size_t>(owner) == i) continue;
      const auto node = static_cast<Index>(sc.m_node - &psb->m_nodes[0]);
      const auto face = static_cast<Index>(sc.m_face - &soft[static_cast<std::size_t>(owner)]->m_faces[0]);
      out.push_back({static_cast<Index>(i), node, static_cast<Index>(owner), face});
    }
  }
  std::sort(out.begin(), out.end());
  out.erase(std::unique(out.begin(), out.end()), out.end());
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

struct PairKey {
  Index a, b;
  bool operator<(const PairKey& o) const { return a != o.a ? a < o.a : b < o.b; }
};
PairKey pairOf(Index x, Index y) { return {std::min(x, y), std::max(x, y)}; }

}  // namespace

const char* toString(Pipeline p) { return p == Pipeline::Sensors ? "sensors" : "bullet"; }
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

RunResult runPipeline(const Scene& scene, Pipeline pipeline, const RunOptions& opt) {
  const auto run_start = Clock::now();
  RunResult r;
  r.scene = scene.name;
  if (const SceneInfo* info = findScene(scene.name)) r.scene_number = info->number;
  r.title = scene.title;
  r.scale = scene.scale;
  r.note = scene.note;
  r.pipeline = pipeline;
  r.bodies = scene.bodies.size();
  r.resolution = scene.resolution();
  r.steps = opt.steps ? opt.steps : scene.default_steps;
  for (const SoftBodySpec& b : scene.bodies) r.vertices += b.mesh.vertices.size();
  r.has_strict = opt.truth == TruthMode::Strict || opt.truth == TruthMode::Both;
  r.has_full = opt.truth == TruthMode::Full || opt.truth == TruthMode::Both;
  r.has_sensor_figures = pipeline == Pipeline::Sensors;
  const std::size_t warmup = opt.warmup ? std::min(opt.warmup, r.steps - 1)
                                        : std::min<std::size_t>(10, std::max<std::size_t>(1, r.steps / 10));

  resetPeakRss();
  WorldOptions wo;
  if (pipeline == Pipeline::Sensors) {
    if (!SensorPipeline::available())
      throw Error(ErrorCode::InvalidArgument, "this psc_demo was built without psc::bullet: use --pipeline bullet");
    wo.soft_collision_flags = SensorPipeline::bodyCollisionFlags();
  }
  SceneWorld sw(scene, wo);
  std::unique_ptr<SensorPipeline> sensors;
  if (pipeline == Pipeline::Sensors) sensors = std::make_unique<SensorPipeline>(sw);
  ZoneTimer zone("Deformable Collision");

  TruthSettings ts;
  ts.strict = r.has_strict;
  ts.full = r.has_full;
  // Bullet decides in btScalar: a pair this close to the radius may go either way on rounding.
  const double scalar_eps = std::numeric_limits<btScalar>::epsilon();
  GroundTruth truth;
  TriangleGrid pen_grid;
  std::vector<TruthBody> bodies;
  std::vector<ContactKey> found;
  std::set<PairKey> truth_pairs, found_pairs;
  const TruthResult* last_truth = nullptr;

  double hook_ms = 0.0, detect_ms = 0.0;
  Clock::time_point detect_start;
  double worst_strict = 1.0, worst_full = 1.0;
  std::size_t exact_total = 0, flagged_total = 0;
  long rounds_total = 0;
  std::vector<double> detect_per_step, refit_per_step, zone_per_step, sensor_per_step, exact_per_step;

  // Measurement inside the step, where contacts were just decided: positions are m_x (predicted)
  // and m_q (previous), exactly what CollideVF_SS used.
  sw.world().before_collision = [&] {
    zone.arm(true);
    detect_start = Clock::now();
  };
  sw.world().after_collision = [&] {
    zone.arm(false);
    detect_ms = msSince(detect_start);
    const auto h0 = Clock::now();
    collectFound(sw, found);
    r.contacts_found_total += found.size();
    if (pipeline == Pipeline::Bullet) exact_total += countVFExactTests(sw.world());
    if (opt.truth != TruthMode::None) {
      const auto t0 = Clock::now();
      extractBodies(sw, bodies, true);
      ts.band_absolute = 16.0 * scalar_eps * coordinateScale(bodies);
      const TruthResult& tr = truth.compute(bodies, ts);
      last_truth = &tr;
      r.truth_seconds += msSince(t0) / 1000.0;
      std::size_t in_strict = 0, in_full = 0, outside = 0;
      found_pairs.clear();
      for (const ContactKey& k : found) {
        found_pairs.insert(pairOf(k.vertex_body, k.triangle_body));
        const TruthContact* c = tr.find(k);
        if (c && c->strict == Membership::Inside) ++in_strict;
        if (c && c->full == Membership::Inside) ++in_full;
        if (r.has_full && (!c || c->full == Membership::Outside)) ++outside;
      }
      truth_pairs.clear();
      for (const TruthContact& c : tr.contacts) {
        if (c.strict == Membership::Inside) {
          const TruthBody& tb = bodies[c.key.triangle_body];
          const Triangle& t = tb.triangles[c.key.triangle];
          const double cross2 = (tb.x[t[1]] - tb.x[t[0]]).cross(tb.x[t[2]] - tb.x[t[0]]).squaredNorm();
          r.truth_strict_untestable += cross2 <= double(SIMD_EPSILON);
        }
        const Membership widest = r.has_full ? c.full : c.strict;
        if (widest == Membership::Inside) truth_pairs.insert(pairOf(c.key.vertex_body, c.key.triangle_body));
        r.truth_ambiguous += (c.strict == Membership::Ambiguous || c.full == Membership::Ambiguous);
      }
      for (const PairKey& p : truth_pairs) r.truth_pairs_found += found_pairs.count(p);
      r.truth_pairs_total += truth_pairs.size();
      r.truth_strict_total += tr.strict_inside;
      r.truth_full_total += tr.full_inside;
      r.found_in_strict += in_strict;
      r.found_in_full += in_full;
      r.contacts_outside_truth += outside;
      if (tr.strict_inside) worst_strict = std::min(worst_strict, double(in_strict) / double(tr.strict_inside));
      if (tr.full_inside) worst_full = std::min(worst_full, double(in_full) / double(tr.full_inside));
    }
    hook_ms += msSince(h0);
  };

  // Far enough out to mean the simulation blew up, not that a body bounced.
  double far_out = 1.0;
  for (const SoftBodySpec& b : scene.bodies)
    for (const Vec3& v : b.mesh.vertices) far_out = std::max(far_out, v.cwiseAbs().maxCoeff());
  far_out *= 1000.0;

  std::unique_ptr<FrameSeries> frames;
  if (!opt.frames_dir.empty()) {
    frames = std::make_unique<FrameSeries>(
        opt.frames_dir, opt.frames_name.empty() ? scene.name + "_" + toString(pipeline) : opt.frames_name);
    std::vector<std::pair<Vec3, Vec3>> boxes;
    for (const StaticBoxSpec& b : scene.statics) boxes.emplace_back(b.center, b.half_extents);
    frames->writeStatic(boxes);
  }

  for (std::size_t step = 0; step < r.steps; ++step) {
    hook_ms = 0.0;
    detect_ms = 0.0;
    const auto t0 = Clock::now();
    sw.step();
    const double step_ms = msSince(t0) - hook_ms;
    const double refit_ms = sw.softSolver().lastFaceRefitMs();
    double collision_ms = refit_ms;
    const double zone_ms = zone.takeMs();
    zone.takeCount();
    SensorStepFigures f;
    if (pipeline == Pipeline::Bullet) {
      collision_ms += zone_ms;
    } else {
      f = sensors->takeStep();
      collision_ms += f.ms_sensor + f.ms_exact + zone_ms;  // zone_ms: pairs handed back to Bullet
      exact_total += f.exact_tests;
      flagged_total += f.flagged_pairs;
      rounds_total += f.rounds;
      r.particles = std::max(r.particles, f.particles);
      r.round_cap_hits += f.round_cap_hits;
      r.repartitions += f.repartitions;
      r.fallback_pairs += f.fallback_pairs;
      if (r.pipeline_error.empty() && !f.error.empty()) r.pipeline_error = f.error;
    }
    if (step >= warmup) {
      r.collision_ms_per_step.push_back(collision_ms);
      r.step_ms_per_step.push_back(step_ms);
      detect_per_step.push_back(detect_ms);
      refit_per_step.push_back(refit_ms);
      zone_per_step.push_back(zone_ms);
      sensor_per_step.push_back(f.ms_sensor);
      exact_per_step.push_back(f.ms_exact);
    }

    if (diverged(sw, far_out)) {
      r.diverged_at_step = static_cast<long>(step);
      r.steps = step + 1;
      break;
    }

    // After the step: what the user sees. Vertices inside another closed body beyond the margins.
    if (opt.penetration) {
      extractBodies(sw, bodies, false);
      const Penetration pen = measurePenetration(bodies, pen_grid);
      if (pen.vertices) {
        ++r.penetration_steps;
        r.max_penetration = std::max(r.max_penetration, pen.max_depth);
      }
    }

    if (frames && step % std::max<std::size_t>(1, opt.frame_every) == 0) {
      extractBodies(sw, bodies, false);
      std::vector<FrameBody> fb(bodies.size());
      SensorView view;
      if (sensors) view = sensors->view();
      for (std::size_t b = 0; b < bodies.size(); ++b) {
        fb[b].x = bodies[b].x;
        fb[b].triangles = &bodies[b].triangles;
        fb[b].contact.assign(bodies[b].x.size(), 0);
        fb[b].missed.assign(bodies[b].x.size(), 0);
        if (sensors && b < view.region_of.size() && !view.region_of[b].empty()) {
          fb[b].region = view.region_of[b];
          fb[b].flagged.assign(bodies[b].x.size(), 0);
          for (std::size_t v = 0; v < fb[b].region.size(); ++v) {
            const auto reg = static_cast<std::size_t>(fb[b].region[v]);
            fb[b].flagged[v] = reg < view.region_flagged[b].size() ? view.region_flagged[b][reg] : 0;
          }
        }
      }
      const auto markTriangle = [&](std::vector<char> FrameBody::*member, Index body, Index tri) {
        for (Index v : bodies[body].triangles[tri]) (fb[body].*member)[v] = 1;
      };
      for (const ContactKey& k : found) {
        fb[k.vertex_body].contact[k.vertex] = 1;
        markTriangle(&FrameBody::contact, k.triangle_body, k.triangle);
      }
      if (last_truth) {
        // Truth contacts of this step's collision pass (strict if asked, else full) not found.
        for (const TruthContact& c : last_truth->contacts) {
          const Membership m = r.has_strict ? c.strict : c.full;
          if (m != Membership::Inside || std::binary_search(found.begin(), found.end(), c.key)) continue;
          fb[c.key.vertex_body].missed[c.key.vertex] = 1;
          markTriangle(&FrameBody::missed, c.key.triangle_body, c.key.triangle);
        }
      }
      if (!sensors)
        for (std::size_t b = 0; b < fb.size(); ++b) fb[b].flagged = fb[b].contact;
      std::vector<FrameParticle> parts;
      for (const auto& p : view.particles) {
        FrameParticle fp;
        fp.x = bodies[p.body].x[p.vertex];
        fp.body = static_cast<int>(p.body);
        fp.region = static_cast<int>(p.region);
        fp.flagged = p.region < view.region_flagged[p.body].size() && view.region_flagged[p.body][p.region];
        parts.push_back(fp);
      }
      frames->writeFrame(step, static_cast<double>(step + 1) * scene.dt, fb, parts);
    }
  }
  if (frames) frames->finish();

  const double steps = static_cast<double>(r.steps);
  r.recall_strict = r.truth_strict_total ? double(r.found_in_strict) / double(r.truth_strict_total) : 1.0;
  r.recall_full = r.truth_full_total ? double(r.found_in_full) / double(r.truth_full_total) : 1.0;
  r.recall_strict_worst_step = worst_strict;
  r.recall_strict_testable = r.truth_strict_total > r.truth_strict_untestable
                                 ? double(r.found_in_strict) / double(r.truth_strict_total - r.truth_strict_untestable)
                                 : 1.0;
  r.recall_full_worst_step = worst_full;
  r.pair_recall = r.truth_pairs_total ? double(r.truth_pairs_found) / double(r.truth_pairs_total) : 1.0;
  r.exact_tests_per_step = double(exact_total) / steps;
  r.flagged_pairs_per_step = double(flagged_total) / steps;
  r.rounds_per_step = double(rounds_total) / steps;
  r.collision_ms_median = median(r.collision_ms_per_step);
  r.step_ms_median = median(r.step_ms_per_step);
  const auto mean = [](const std::vector<double>& v) {
    double s = 0;
    for (double x : v) s += x;
    return v.empty() ? 0.0 : s / double(v.size());
  };
  r.collision_ms_mean = mean(r.collision_ms_per_step);
  r.step_ms_mean = mean(r.step_ms_per_step);
  r.detect_ms_median = median(detect_per_step);
  r.face_refit_ms_median = median(refit_per_step);
  r.zone_ms_median = median(zone_per_step);
  r.sensor_step_ms_median = median(sensor_per_step);
  r.exact_stage_ms_median = median(exact_per_step);
  if (sensors) {
    r.midphase_bytes_per_vertex = sensors->midphaseBytesPerVertex();
  } else {
    std::size_t bytes = 0;
    for (btSoftBody* b : sw.softBodies()) bytes += bulletMidphaseBytes(*b);
    r.midphase_bytes_per_vertex = r.vertices ? double(bytes) / double(r.vertices) : 0.0;
  }
  r.peak_rss_mb = peakRssMb();
  r.wall_seconds = msSince(run_start) / 1000.0;
  return r;
}

}  // namespace psc::demo
