// psc_exact_bench: the cost of one exact test (psc::bullet::Settings::exact) on real candidate
// pairs. A demo scene is simulated with the plugin (Bullet's test) and, at the step with the most
// candidates, the candidate pairs and every node's m_x / m_q are captured; each benchmark then runs
// psc::bullet::collideCandidates (what the plugin runs per body pair and direction, contacts
// appended to m_scontacts included) on exactly those pairs.
//
//   build/release/demos/psc_exact_bench [--benchmark_filter=...] [--benchmark_repetitions=5]
//                                       [--bullet-default-alignment]
//
// Bullet's large arrays start on cache lines (psc::bullet::alignLargeBulletBlocks, as in psc_demo)
// unless --bullet-default-alignment keeps Bullet's own allocator.
// The counter per_test is the wall time of one test (seconds, e.g. 45n = 45 ns); ratios to the
// Bullet row of the same scene are what README "Exact tests" quotes. The rows `*_pairwise` run
// the same tests pair by pair instead of eight at a time with AVX
// (bullet_plugin/src/vf_lanes.h): what the plugin does without AVX or in double precision.
#include "../bullet_plugin/src/vf_lanes.h"
#include "plugin_scene.h"

#include <benchmark/benchmark.h>

#include <algorithm>
#include <cstdio>
#include <exception>
#include <map>
#include <memory>
#include <string>
#include <vector>

namespace {

using psc::bullet::ExactTest;

/// One direction of one body pair: the candidates of (vertex body, triangle body).
struct Group {
  btSoftBody* node_body;
  btSoftBody* face_body;
  std::vector<psc::CandidatePair> pairs;
};

/// A scene frozen at the moment the exact stage ran, with its candidate pairs.
struct Capture {
  psc::demo::PluginScene sim;
  std::vector<Group> groups;
  std::size_t tests = 0;
  std::size_t step = 0;
};

Capture capture(const std::string& name, std::size_t resolution, double scale, std::size_t steps) {
  Capture c;
  psc::demo::SceneParams params;
  params.resolution = resolution;
  params.scale = scale;
  c.sim = psc::demo::makePluginScene(name, params);
  psc::demo::SceneWorld& world = *c.sim.world;
  const std::shared_ptr<psc::bullet::Plugin>& plugin = c.sim.plugin;

  std::vector<std::vector<std::pair<btVector3, btVector3>>> best_nodes;
  std::vector<psc::CandidatePair> best_pairs;
  std::size_t step = 0;
  world.world().after_collision = [&] {
    const std::vector<psc::CandidatePair>& pairs = plugin->sensorWorld().lastResult().candidates;
    if (pairs.size() <= best_pairs.size()) return;
    best_pairs = pairs;
    c.step = step;
    best_nodes.clear();
    for (btSoftBody* body : world.softBodies()) {
      best_nodes.emplace_back();
      for (int i = 0; i < body->m_nodes.size(); ++i) best_nodes.back().emplace_back(body->m_nodes[i].m_x, body->m_nodes[i].m_q);
    }
  };
  for (; step < steps; ++step) world.step();
  world.world().after_collision = nullptr;

  // Back to the captured moment, and the candidates grouped by (vertex body, triangle body).
  const std::vector<btSoftBody*>& bodies = world.softBodies();
  std::map<psc::BodyId, btSoftBody*> by_id;
  for (std::size_t b = 0; b < bodies.size(); ++b) {
    for (int i = 0; i < bodies[b]->m_nodes.size(); ++i) {
      bodies[b]->m_nodes[i].m_x = best_nodes[b][std::size_t(i)].first;
      bodies[b]->m_nodes[i].m_q = best_nodes[b][std::size_t(i)].second;
    }
    bodies[b]->m_scontacts.resize(0);
    if (auto id = plugin->bodyId(bodies[b])) by_id[*id] = bodies[b];
  }
  for (const psc::CandidatePair& p : best_pairs) {
    if (c.groups.empty() || c.groups.back().node_body != by_id.at(p.vertex_body) ||
        c.groups.back().face_body != by_id.at(p.triangle_body))
      c.groups.push_back({by_id.at(p.vertex_body), by_id.at(p.triangle_body), {}});
    c.groups.back().pairs.push_back(p);
  }
  c.tests = best_pairs.size();
  return c;
}

/// `lanes` false: the tests pair by pair (the plugin's path without AVX or in double precision),
/// the same contacts.
void run(benchmark::State& state, const Capture& c, ExactTest test, bool lanes = true) {
  psc::bullet::detail::allowVfLanes(lanes);
  std::size_t contacts = 0, robust = 0, crossings = 0;
  for (auto _ : state) {
    contacts = robust = crossings = 0;
    for (const Group& g : c.groups) {
      const psc::bullet::ExactCounts n = psc::bullet::collideCandidates(
          test, *g.node_body, *g.face_body, g.pairs.data(), g.pairs.data() + g.pairs.size());
      contacts += n.contacts;
      robust += n.robust;
      crossings += n.crossings;
    }
    state.PauseTiming();
    for (const Group& g : c.groups) g.node_body->m_scontacts.resize(0);
    state.ResumeTiming();
  }
  state.counters["tests"] = double(c.tests);
  state.counters["contacts"] = double(contacts);
  state.counters["robust"] = double(robust);
  state.counters["crossings"] = double(crossings);
  state.counters["per_test"] =
      benchmark::Counter(double(c.tests), benchmark::Counter::kIsIterationInvariantRate | benchmark::Counter::kInvert);
  psc::bullet::detail::allowVfLanes(true);
}

struct Case {
  const char* label;
  const char* scene;
  std::size_t resolution;
  double scale;
  std::size_t steps;
};

}  // namespace

int main(int argc, char** argv) {
  psc::demo::alignBulletBlocksUnlessAsked(argc, argv);
  benchmark::Initialize(&argc, argv);
  if (benchmark::ReportUnrecognizedArguments(argc, argv)) return 1;
  // Real pairs: spheres meeting, a fast impact (large motion terms), and the mesh scene whose
  // small triangles Bullet's test refuses.
  const Case cases[] = {{"head_on", "head_on", 1000, 1.0, 60},
                        {"fast_impact", "fast_impact", 1000, 1.0, 25},
                        {"mesh", "mesh", 1000, 1.0, 100}};
  std::vector<std::unique_ptr<Capture>> captures;
  for (const Case& k : cases) {
    try {
      captures.push_back(std::make_unique<Capture>(capture(k.scene, k.resolution, k.scale, k.steps)));
    } catch (const std::exception& e) {  // e.g. scene 8 without its default mesh file installed
      std::fprintf(stderr, "psc_exact_bench: %s skipped: %s\n", k.label, e.what());
      continue;
    }
    const Capture& c = *captures.back();
    std::fprintf(stderr, "psc_exact_bench: %s: %zu candidate pairs captured at step %zu\n", k.label, c.tests, c.step);
    for (ExactTest test : {ExactTest::Bullet, ExactTest::Robust, ExactTest::Continuous})
      benchmark::RegisterBenchmark((std::string(k.label) + "/" + psc::bullet::toString(test)).c_str(),
                                   [&c, test](benchmark::State& s) { run(s, c, test); })
          ->Unit(benchmark::kMicrosecond);
    if (psc::bullet::detail::vfLanesEnabled()) {
      for (ExactTest test : {ExactTest::Bullet, ExactTest::Robust, ExactTest::Continuous})
        benchmark::RegisterBenchmark((std::string(k.label) + "/" + psc::bullet::toString(test) + "_pairwise").c_str(),
                                     [&c, test](benchmark::State& s) { run(s, c, test, false); })
            ->Unit(benchmark::kMicrosecond);
    }
  }
  benchmark::RunSpecifiedBenchmarks();
  benchmark::Shutdown();
  return 0;
}
