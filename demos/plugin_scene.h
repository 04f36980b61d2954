// A demo scene simulated with the plugin on every soft body (Bullet's exact test, default
// settings): what the benchmarks that capture real inputs (psc_exact_bench, psc_midphase_bench)
// step to the moment they measure.
#pragma once

#include "bullet_scene.h"
#include "psc/bullet/bullet.h"
#include "scenes.h"

#include <memory>
#include <string>

namespace psc::demo {

struct PluginScene {
  std::unique_ptr<Scene> scene;
  std::unique_ptr<SceneWorld> world;
  std::shared_ptr<psc::bullet::Plugin> plugin;  ///< also held by the world, which outlives no body
};

/// Scene `name` with `params`, soft-soft collision through the plugin only (Bullet's own VF_SS
/// off, soft-rigid by SDF_RS).
inline PluginScene makePluginScene(const std::string& name, const SceneParams& params) {
  PluginScene p;
  p.scene = std::make_unique<Scene>(makeScene(name, params));
  WorldOptions options;
  options.soft_collision_flags = btSoftBody::fCollision::SDF_RS;
  p.world = std::make_unique<SceneWorld>(*p.scene, options);
  psc::bullet::Settings settings;
  settings.opt_in = psc::bullet::OptIn::Explicit;
  p.plugin = std::make_shared<psc::bullet::Plugin>(psc::bullet::install(p.world->world(), settings));
  for (btSoftBody* body : p.world->softBodies()) p.plugin->setEnabled(body, true);
  p.world->attach(p.plugin);
  return p;
}

/// The benchmarks' start: takes `--bullet-default-alignment` out of the arguments (before Google
/// Benchmark sees them) and, unless it was given, puts Bullet's large arrays on cache lines
/// (psc::bullet::alignLargeBulletBlocks), as psc_demo does for every pipeline.
inline void alignBulletBlocksUnlessAsked(int& argc, char** argv) {
  bool default_alignment = false;
  int kept = 1;
  for (int i = 1; i < argc; ++i) {
    if (std::string(argv[i]) == "--bullet-default-alignment") default_alignment = true;
    else argv[kept++] = argv[i];
  }
  argc = kept;
  if (!default_alignment) psc::bullet::alignLargeBulletBlocks();
}

}  // namespace psc::demo
