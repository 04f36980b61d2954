// psc_midphase_bench: the core's step (SensorWorld::step(): refit, particles, culls, candidates) on
// recorded frames of a demo scene, with and without the sensor stage. A scene is simulated with
// the plugin (Bullet's test) and every node's m_x / m_q is recorded over a window of steps in
// contact; each benchmark then builds a core world over the same Bullet bodies (the positions read
// in place from the 256-byte nodes, as the plugin reads them), puts each recorded frame back into
// the nodes and times step() alone. Neither Bullet's solver nor the exact stage runs, and both
// flaggings see the very same positions, so their difference is the sensors' own: what the
// ablation (`psc_demo --pipeline all`, bounds / sensors) measures amid a whole simulation.
//
//   build/release/demos/psc_midphase_bench [--benchmark_filter=...] [--benchmark_repetitions=5]
//                                          [--bullet-default-alignment]
//
// Bullet's large arrays start on cache lines (psc::bullet::alignLargeBulletBlocks, as in psc_demo)
// unless --bullet-default-alignment keeps Bullet's own allocator.
//
// tori_pile_8x50000/sensors and /bounds are the speed target's 8 tori × 50,000 vertices over its 40
// steps (recorded when first selected); /refit and /read time the refit alone against the memory it
// reads.
//
// Counters: ms_per_step (the mean wall time of step() over the frames), candidates and probes per
// step, and the region pairs the sensors proved apart. The frames are replayed forward, then
// backward, so the particles track a motion that does not jump; the timing pauses only while a
// frame is written into the nodes. The `sensors_self` rows switch every body's self-collision on
// (rest shape: the first recorded frame) and count its candidates too (self_candidates): beside
// `sensors`, what self-collision costs where the bodies do not fold.
#include "plugin_scene.h"
#include "psc/world.h"

#include <benchmark/benchmark.h>

#include <chrono>
#include <cstdio>
#include <exception>
#include <memory>
#include <string>
#include <vector>

namespace {

/// Every node's (m_x, m_q) of every body at one step.
using Frame = std::vector<std::vector<std::pair<btVector3, btVector3>>>;

/// A scene simulated with the plugin, and its nodes recorded at each step of a window.
struct Recording {
  psc::demo::PluginScene sim;
  std::vector<Frame> frames;
  std::vector<std::size_t> candidates;  ///< the plugin's candidate pairs at each recorded step
  std::size_t first_step = 0;
};

/// Steps `from` to `from + count − 1` of the scene, recorded.
Recording record(const std::string& name, const psc::demo::SceneParams& params, std::size_t from, std::size_t count) {
  Recording r{psc::demo::makePluginScene(name, params), {}, {}, from};
  psc::demo::SceneWorld& world = *r.sim.world;
  std::size_t step = 0;
  world.world().after_collision = [&] {
    if (step < from) return;
    Frame f;
    for (btSoftBody* body : world.softBodies()) {
      f.emplace_back();
      for (int i = 0; i < body->m_nodes.size(); ++i) f.back().emplace_back(body->m_nodes[i].m_x, body->m_nodes[i].m_q);
    }
    r.frames.push_back(std::move(f));
    r.candidates.push_back(r.sim.plugin->sensorWorld().lastResult().candidates.size());
  };
  for (; step < from + count; ++step) world.step();
  world.world().after_collision = nullptr;
  return r;
}

void put(const Recording& r, const Frame& f) {
  const std::vector<btSoftBody*>& bodies = r.sim.world->softBodies();
  for (std::size_t b = 0; b < bodies.size(); ++b)
    for (int i = 0; i < bodies[b]->m_nodes.size(); ++i) {
      bodies[b]->m_nodes[i].m_x = f[b][std::size_t(i)].first;
      bodies[b]->m_nodes[i].m_q = f[b][std::size_t(i)].second;
    }
}

/// A core world over Bullet bodies, as the plugin builds it (its default core settings, the
/// bodies' margins, the positions read in place), with `flagging`, and with every body's
/// self-collision on when `self` (its rest shape: the positions of the first recorded frame).
psc::SensorWorld coreWorld(const std::vector<btSoftBody*>& bodies, psc::Flagging flagging, bool self = false) {
  psc::SensorSettings settings = psc::bullet::Settings{}.sensors;
  settings.flagging = flagging;
  psc::SensorWorld world(settings);
  for (btSoftBody* body : bodies) {
    psc::BodyDesc desc;
    for (int f = 0; f < body->m_faces.size(); ++f) {
      psc::Triangle t;
      for (int k = 0; k < 3; ++k) t[std::size_t(k)] = psc::Index(body->m_faces[f].m_n[k] - &body->m_nodes[0]);
      desc.triangles.push_back(t);
    }
    const std::size_t n = std::size_t(body->m_nodes.size()), stride = sizeof(btSoftBody::Node);
    desc.positions = psc::PositionView(body->m_nodes[0].m_x.m_floats, n, stride);
    desc.previous = psc::PositionView(body->m_nodes[0].m_q.m_floats, n, stride);
    desc.margin = body->getCollisionShape()->getMargin();
    desc.self_collision = self;
    world.addBody(desc);
  }
  return world;
}

void run(benchmark::State& state, const Recording& r, psc::Flagging flagging, bool self) {
  if (self) put(r, r.frames.front());  // the rest shape
  psc::SensorWorld world = coreWorld(r.sim.world->softBodies(), flagging, self);
  // Forward, then backward: frame k's positions after frame k+1's are a motion of the same size.
  std::vector<std::size_t> order;
  for (std::size_t k = 0; k < r.frames.size(); ++k) order.push_back(k);
  for (std::size_t k = r.frames.size(); k-- > 1;) order.push_back(k - 1);
  // One pass untimed: partitioning, and the particles brought to the contacts.
  for (std::size_t k : order) {
    put(r, r.frames[k]);
    world.step();
  }
  double seconds = 0.0, candidates = 0.0, probes = 0.0, separated = 0.0, self_candidates = 0.0, steps = 0.0;
  bool same = true;
  for (auto _ : state) {
    for (std::size_t k : order) {
      state.PauseTiming();
      put(r, r.frames[k]);
      state.ResumeTiming();
      const auto t0 = std::chrono::steady_clock::now();
      const psc::StepResult& s = world.step();
      seconds += std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
      candidates += double(s.candidates.size());
      probes += double(s.stats.candidate_probes);
      separated += double(s.stats.region_pairs_separated);
      self_candidates += double(s.stats.self_candidate_pairs);
      steps += 1.0;
      // The candidates between bodies do not depend on the flagging, nor on where the particles
      // are, nor on self-collision.
      same = same && s.candidates.size() - s.stats.self_candidate_pairs == r.candidates[k];
    }
  }
  if (!same) state.SkipWithError("the candidates differ from the plugin's at the same step");
  state.counters["ms_per_step"] = 1e3 * seconds / steps;
  state.counters["candidates"] = candidates / steps;
  state.counters["probes"] = probes / steps;
  state.counters["separated"] = separated / steps;
  if (self) state.counters["self_candidates"] = self_candidates / steps;
}

/// The refit against the memory it reads, on the speed target's largest pile (8 tori × 50,000
/// vertices, built once, never stepped by Bullet). Per iteration and body, untimed, each node is
/// written as predictMotion writes it (m_q = m_x, m_x moved), and then, timed, either the core's
/// refit of that body (SensorWorld::refitNow, what the plugin's solver calls right there) or a
/// plain loop that only reads m_x and m_q of every node: the floor of any midphase that looks at
/// every vertex each step. Counter: ns_per_vertex.
void refitOrRead(benchmark::State& state, bool refit) {
  static std::unique_ptr<psc::demo::PluginScene> pile;
  if (!pile) {
    psc::demo::SceneParams params;
    params.resolution = 50000;
    params.bodies = 8;
    pile = std::make_unique<psc::demo::PluginScene>(psc::demo::makePluginScene("tori_pile", params));
  }
  const std::vector<btSoftBody*>& bodies = pile->world->softBodies();
  psc::SensorWorld world = coreWorld(bodies, psc::Flagging::SensorsAndBounds);
  world.step();  // partitions every body
  const std::vector<psc::BodyId> ids = world.bodyIds();
  double seconds = 0.0, vertices = 0.0;
  float sink = 0.0f;
  btScalar shift = btScalar(1e-4);
  for (auto _ : state) {
    shift = -shift;
    for (std::size_t b = 0; b < bodies.size(); ++b) {
      btSoftBody::Node* nodes = &bodies[b]->m_nodes[0];
      const int n = bodies[b]->m_nodes.size();
      state.PauseTiming();
      for (int i = 0; i < n; ++i) {
        nodes[i].m_q = nodes[i].m_x;
        nodes[i].m_x.setX(nodes[i].m_x.x() + shift);
      }
      state.ResumeTiming();
      const auto t0 = std::chrono::steady_clock::now();
      if (refit) {
        if (!world.refitNow(ids[b])) state.SkipWithError("refitNow did not refit");
      } else {
        float sum = 0.0f;
        for (int i = 0; i < n; ++i) sum += nodes[i].m_x.y() + nodes[i].m_q.z();
        sink += sum;
      }
      seconds += std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
      vertices += double(n);
    }
  }
  benchmark::DoNotOptimize(sink);
  state.counters["ns_per_vertex"] = 1e9 * seconds / vertices;
}

struct Case {
  const char* label;
  const char* scene;
  std::size_t resolution, bodies, from, count;
};

}  // namespace

int main(int argc, char** argv) {
  psc::demo::alignBulletBlocksUnlessAsked(argc, argv);
  benchmark::Initialize(&argc, argv);
  if (benchmark::ReportUnrecognizedArguments(argc, argv)) return 1;
  // The suite's heaviest scenes at the ablation's resolution, and the 8-tori pile of the speed target.
  // head_on: its steps 10–89 (in contact until about step 45, then apart) and the contact alone,
  // where self-collision's cost lies (sensors_self).
  const Case cases[] = {{"head_on_600", "head_on", 600, 0, 10, 80},
                        {"head_on_contact", "head_on", 600, 0, 10, 36},
                        {"mixed_pile_600", "mixed_pile", 600, 0, 100, 40},
                        {"mesh_600", "mesh", 600, 0, 100, 40},
                        {"tori_pile_600", "tori_pile", 600, 0, 100, 40},
                        {"tori_pile_8x2000", "tori_pile", 2000, 8, 60, 40}};
  std::vector<std::unique_ptr<Recording>> recordings;
  for (const Case& k : cases) {
    try {
      psc::demo::SceneParams params;
      params.resolution = k.resolution;
      params.bodies = k.bodies;
      recordings.push_back(std::make_unique<Recording>(record(k.scene, params, k.from, k.count)));
    } catch (const std::exception& e) {  // e.g. the mesh scene without its default mesh file installed
      std::fprintf(stderr, "psc_midphase_bench: %s skipped: %s\n", k.label, e.what());
      continue;
    }
    const Recording& r = *recordings.back();
    std::fprintf(stderr, "psc_midphase_bench: %s: steps %zu to %zu recorded\n", k.label, r.first_step,
                 r.first_step + r.frames.size() - 1);
    // sensors_self: every body's self-collision on, for its overhead where (in these recordings,
    // simulated without it) the bodies barely touch themselves.
    struct Variant {
      psc::Flagging flagging;
      bool self;
      const char* name;
    };
    for (const Variant& v : {Variant{psc::Flagging::SensorsAndBounds, false, "sensors"},
                             Variant{psc::Flagging::Bounds, false, "bounds"},
                             Variant{psc::Flagging::SensorsAndBounds, true, "sensors_self"}})
      benchmark::RegisterBenchmark((std::string(k.label) + "/" + v.name).c_str(),
                                   [&r, v](benchmark::State& s) { run(s, r, v.flagging, v.self); })
          ->Unit(benchmark::kMillisecond);
  }
  // The scale target's pile (8 tori × 50,000 vertices, its 40 steps as `psc_demo --scene tori_pile
  // --bodies 8 --resolution 50000 --steps 40` runs them): recorded on first use only (about half a
  // minute and 0.6 GB), so that other filters do not pay for it.
  for (const auto& [flagging, name] :
       {std::pair{psc::Flagging::SensorsAndBounds, "sensors"}, std::pair{psc::Flagging::Bounds, "bounds"}})
    benchmark::RegisterBenchmark((std::string("tori_pile_8x50000/") + name).c_str(),
                                 [flagging = flagging](benchmark::State& s) {
                                   static std::unique_ptr<Recording> pile;
                                   if (!pile) {
                                     psc::demo::SceneParams params;
                                     params.resolution = 50000;
                                     params.bodies = 8;
                                     pile = std::make_unique<Recording>(record("tori_pile", params, 0, 40));
                                   }
                                   run(s, *pile, flagging, false);
                                 })
        ->Unit(benchmark::kMillisecond);
  for (const auto& [refit, name] : {std::pair{true, "refit"}, std::pair{false, "read"}})
    benchmark::RegisterBenchmark((std::string("tori_pile_8x50000/") + name).c_str(),
                                 [refit = refit](benchmark::State& s) { refitOrRead(s, refit); })
        ->Unit(benchmark::kMillisecond);
  benchmark::RunSpecifiedBenchmarks();
  benchmark::Shutdown();
  return 0;
}
