// The particle-sensor pipeline as the benchmark drives it: psc::bullet installed on a SceneWorld,
// every soft body enabled explicitly (Settings::opt_in = Explicit) and without VF_SS, so Bullet
// builds no face tree for it. Everything that touches the plugin's API is in this file; without
// psc::bullet (PSC_DEMO_HAVE_PLUGIN undefined) available() is false and the constructor throws.
#pragma once

#include "bullet_scene.h"
#include "psc/bullet/settings.h"
#include "psc/settings.h"
#include "step_record.h"

#include <memory>
#include <string>
#include <vector>

namespace psc::demo {

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

  /// What our pipeline runs with; each member goes to psc::bullet::Settings.
  struct Options {
    /// Settings::sensors.flagging: SensorsAndBounds (the default), Bounds (the ablation: boxes
    /// only) or Sensors (the thesis's flag-only mode).
    psc::Flagging flagging = psc::Flagging::SensorsAndBounds;
    /// The exact test, "bullet", "robust" or "continuous" (psc::bullet::ExactTest).
    std::string exact = "bullet";
    /// Settings::sensors.motion_bound, "radius" (MotionBound::Radius), "ahead" (MotionBound::Ahead)
    /// or "swept" (MotionBound::Swept).
    std::string motion_bound = "radius";
    /// Settings::contacts, "all" (ContactSet::AllPairs) or "nearest" (ContactSet::NearestFace).
    std::string contacts = "all";
    /// Settings::self_collision: every body against itself too (its rest shape: its positions at
    /// the plugin's first step).
    bool self_collision = false;
    bool self_rest_bound = true;  ///< psc::SensorSettings::self_rest_bound
    /// The world's solver calls Plugin::afterPredictMotion after each body's predictMotion (what
    /// psc::bullet::SoftBodySolver does), so the sensors refit each body while its nodes are warm;
    /// false: every body is refit in the sensor step, at the first soft-soft pair.
    bool refit_after_predict = true;
    bool runaway_fallback = false;  ///< Settings::runaway_fallback
    bool runaway_sharing = true;    ///< Settings::runaway_sharing
    std::size_t crowded_band = psc::bullet::Settings{}.crowded_band;  ///< Settings::crowded_band
  };
  /// Installs the plugin on `world`'s soft bodies. A text option that names no choice throws
  /// psc::Error(InvalidArgument).
  SensorPipeline(SceneWorld& world, const Options& options);
  ~SensorPipeline();

  /// Adds the plugin's figures of the step that just ended to `record` (times and counts stay 0
  /// when the plugin did not run its sensor step, i.e. Bullet dispatched no soft-soft pair).
  void takeStep(StepRecord& record);
  /// Bytes the core keeps for all bodies (topology, regions, particles), per vertex of the scene.
  double midphaseBytesPerVertex() const;
  SensorView view() const;

 private:
  struct Impl;
  std::shared_ptr<Impl> impl_;
};

}  // namespace psc::demo
