#include "bullet_probe.h"

#include <BulletCollision/BroadphaseCollision/btDbvt.h>
#include <LinearMath/btQuickprof.h>

#include <chrono>
#include <cstring>
#include <vector>

namespace psc::demo {
namespace {

using Clock = std::chrono::steady_clock;

// State of the one live ZoneTimer (Bullet's hooks take plain function pointers, no user data).
struct ZoneState {
  const char* zone = nullptr;
  bool armed = false;
  std::vector<std::pair<bool, Clock::time_point>> stack;
  double ms = 0.0;
  std::size_t count = 0;
  btEnterProfileZoneFunc* prev_enter = nullptr;
  btLeaveProfileZoneFunc* prev_leave = nullptr;
};
ZoneState g_zone;

void enterZone(const char* name) {
  const bool timed = g_zone.armed && name && std::strcmp(name, g_zone.zone) == 0;
  g_zone.stack.emplace_back(timed, timed ? Clock::now() : Clock::time_point{});
}

void leaveZone() {
  if (g_zone.stack.empty()) return;  // a zone entered before we were installed
  const auto [timed, t0] = g_zone.stack.back();
  g_zone.stack.pop_back();
  if (timed) {
    g_zone.ms += std::chrono::duration<double, std::milli>(Clock::now() - t0).count();
    ++g_zone.count;
  }
}

struct CountingCollide : btDbvt::ICollide {
  std::size_t n = 0;
  void Process(const btDbvtNode*, const btDbvtNode*) override { ++n; }
};

}  // namespace

ZoneTimer::ZoneTimer(const char* zone) {
  g_zone = ZoneState{};
  g_zone.zone = zone;
  g_zone.stack.reserve(64);
  g_zone.prev_enter = btGetCurrentEnterProfileZoneFunc();
  g_zone.prev_leave = btGetCurrentLeaveProfileZoneFunc();
  btSetCustomEnterProfileZoneFunc(&enterZone);
  btSetCustomLeaveProfileZoneFunc(&leaveZone);
}

ZoneTimer::~ZoneTimer() {
  btSetCustomEnterProfileZoneFunc(g_zone.prev_enter);
  btSetCustomLeaveProfileZoneFunc(g_zone.prev_leave);
  g_zone = ZoneState{};
}

void ZoneTimer::arm(bool on) { g_zone.armed = on; }

double ZoneTimer::takeMs() {
  const double ms = g_zone.ms;
  g_zone.ms = 0.0;
  return ms;
}

std::size_t ZoneTimer::takeCount() {
  const std::size_t n = g_zone.count;
  g_zone.count = 0;
  return n;
}

std::size_t countVFExactTests(btSoftRigidDynamicsWorld& world) {
  btOverlappingPairCache* cache = world.getBroadphase()->getOverlappingPairCache();
  btDispatcher* dispatcher = world.getDispatcher();
  CountingCollide counter;
  const int n = cache->getNumOverlappingPairs();
  btBroadphasePair* pairs = cache->getOverlappingPairArrayPtr();
  for (int i = 0; i < n; ++i) {
    auto* a = btSoftBody::upcast(static_cast<btCollisionObject*>(pairs[i].m_pProxy0->m_clientObject));
    auto* b = btSoftBody::upcast(static_cast<btCollisionObject*>(pairs[i].m_pProxy1->m_clientObject));
    if (!a || !b || a == b || !dispatcher->needsCollision(a, b)) continue;
    // Same switch as btSoftBody::defaultCollisionHandler: exact case label, not a bit test.
    if (((a->m_cfg.collisions & b->m_cfg.collisions) & btSoftBody::fCollision::SVSmask) != btSoftBody::fCollision::VF_SS)
      continue;
    a->m_ndbvt.collideTT(a->m_ndbvt.m_root, b->m_fdbvt.m_root, counter);
    b->m_ndbvt.collideTT(b->m_ndbvt.m_root, a->m_fdbvt.m_root, counter);
  }
  return counter.n;
}

namespace {
// Counted by walking: trees built by initializeFaceTree bypass btDbvt::insert, so m_leaves is 0.
std::size_t countNodes(const btDbvtNode* n) {
  if (!n) return 0;
  return 1 + (n->isinternal() ? countNodes(n->childs[0]) + countNodes(n->childs[1]) : 0);
}
}  // namespace

std::size_t bulletMidphaseBytes(const btSoftBody& body) {
  return (countNodes(body.m_ndbvt.m_root) + countNodes(body.m_fdbvt.m_root) + countNodes(body.m_cdbvt.m_root)) *
         sizeof(btDbvtNode);
}

}  // namespace psc::demo
