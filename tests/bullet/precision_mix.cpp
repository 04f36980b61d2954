// Compiled by precision_guard.cmake, never by the build: a program that uses psc::bullet. Built
// with the other Bullet precision it must not compile; linked with the other precision's
// libraries it must not link; built consistently it links and runs.
#include "psc/bullet/plugin.h"

int main(int argc, char** argv) {
  // Only the link matters: the world is never touched (argv is non-null at run time).
  if (argc > 1000 && argv != nullptr) {
    auto* world = reinterpret_cast<btSoftRigidDynamicsWorld*>(argv);
    psc::bullet::Plugin plugin = psc::bullet::install(*world);
    return plugin.installed() ? 1 : 2;
  }
  return 0;
}
