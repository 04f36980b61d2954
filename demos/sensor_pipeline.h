// The particle-sensor pipeline as the benchmark drives it: psc::bullet installed on a SceneWorld,
// every soft body enabled explicitly (Settings::opt_in = Explicit) and without VF_SS, so Bullet
// builds no face tree for it. Everything that touches the plugin's API is in this file; without
// psc::bullet (PSC_DEMO_HAVE_PLUGIN undefined) available() is false and the constructor throws.
#pragma once

#include "bullet_scene.h"

#include <memory>
#include <string>
#include <vector>

namespace psc::demo {

/// The plugin's figures for one simulation step (zero when it did not run the sensors this step,
/// i.e. Bullet dispatched no soft-soft pair).
struct SensorStepFigures {
  bool stepped = false;
  std::size_t particles = 0;
  int rounds = 0;
  std::size_t round_cap_hits = 0;
  std::size_t flagged_pairs = 0;
  std::size_t candidate_pairs = 0;
  std::size_t exact_tests = 0;
  std::size_t contacts = 0;
  std::size_t repartitions = 0;
  std::size_t fallback_pairs = 0;  ///< pairs the plugin handed back to Bullet's algorithm
  double ms_sensor = 0.0;          ///< sensor step incl. candidate sets, wall clock
  double ms_exact = 0.0;           ///< exact stage (CollideVF_SS on the candidates), wall clock
  std::string error;
};

/// What a frame shows of the sensors.
struct SensorView {
  std::vector<std::vector<int>> region_of;        ///< per scene body, per vertex; empty if unknown
  std::vector<std::vector<char>> region_flagged;  ///< per scene body, per region
  struct Particle {
    std::size_t body;
    Index vertex;
    Index region;
  };
  std::vector<Particle> particles;
};

class SensorPipeline {
 public:
  static bool available();
  /// m_cfg.collisions for bodies of the sensor world: soft-rigid as usual, no VF_SS.
  static int bodyCollisionFlags();

  explicit SensorPipeline(SceneWorld& world);
  ~SensorPipeline();

  /// Figures of the step that just ended.
  SensorStepFigures takeStep();
  /// Bytes the core keeps for all bodies (topology, regions, particles), per vertex of the scene.
  double midphaseBytesPerVertex() const;
  SensorView view() const;

 private:
  struct Impl;
  std::shared_ptr<Impl> impl_;
};

}  // namespace psc::demo
