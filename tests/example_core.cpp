// The README's core example: two soft spheres meet; the sensors flag where, and hand the exact
// test a short list of (vertex, triangle) candidates instead of all pairs.
#include <psc/psc.h>

#include <cstdio>

int main() {
  psc::TriMesh a = psc::makeSphere(1.0, 2000);
  psc::TriMesh b = psc::makeSphere(1.0, 2000);
  b.translate({2.02, 0.0, 0.0});  // 2 cm apart at 1 m radius

  psc::SensorWorld world;  // default settings: see include/psc/settings.h
  psc::BodyDesc desc;
  desc.margin = 0.02;  // each body's collision margin
  desc.triangles = a.triangles;
  desc.positions = psc::PositionView::of(a.vertices);  // read in place, never copied
  const psc::BodyId ida = world.addBody(desc);
  desc.triangles = b.triangles;
  desc.positions = psc::PositionView::of(b.vertices);
  const psc::BodyId idb = world.addBody(desc);

  for (int step = 0; step < 3; ++step) {
    for (psc::Vec3& p : b.vertices) p.x() -= 0.005;  // b deforms/moves in place; the view sees it
    const psc::StepResult& r = world.step();
    std::printf("step %d: %zu particles, %d rounds, %zu flagged region pairs, %zu candidate pairs\n", step,
                r.stats.particles, r.stats.rounds, r.stats.flagged_pairs, r.stats.candidate_pairs);
  }
  const psc::StepResult& r = world.lastResult();
  if (r.flagged.empty()) return 1;  // the spheres touch: something must be flagged
  const psc::FlaggedPair& f = r.flagged.front();
  std::printf("first flagged pair: region %u of body %u with region %u of body %u (mu = %.4f)\n", f.region_a,
              f.body_a, f.region_b, f.body_b, world.mu(ida, idb));
  return 0;
}
