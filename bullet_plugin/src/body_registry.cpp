#include "body_registry.h"

#include "psc/error.h"

#include <BulletCollision/BroadphaseCollision/btBroadphaseProxy.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <string>
#include <utility>

namespace psc::bullet::detail {
namespace {

// Node positions read in place: m_x is the predicted position once predictMotion has run, m_q the
// position before it (docs/BULLET.md, "A step of a soft-rigid world").
psc::PositionView nodeView(const btSoftBody& body, bool previous) {
  const btSoftBody::Node& first = body.m_nodes[0];
  const btScalar* xyz = previous ? first.m_q.m_floats : first.m_x.m_floats;
  return psc::PositionView(xyz, static_cast<std::size_t>(body.m_nodes.size()), sizeof(btSoftBody::Node));
}

/// Face k is triangle k, so the core's triangle indices are indices into m_faces.
std::vector<psc::Triangle> trianglesOf(const btSoftBody& body, const std::string& name) {
  if (body.m_nodes.size() == 0 || body.m_faces.size() == 0)
    throw psc::Error(psc::ErrorCode::InvalidMesh, name + " has no faces (a rope or a point cloud)");
  const btSoftBody::Node* first = &body.m_nodes[0];
  const std::ptrdiff_t count = body.m_nodes.size();
  std::vector<psc::Triangle> triangles(static_cast<std::size_t>(body.m_faces.size()));
  for (int f = 0; f < body.m_faces.size(); ++f) {
    for (int k = 0; k < 3; ++k) {
      const std::ptrdiff_t node = body.m_faces[f].m_n[k] - first;
      if (node < 0 || node >= count)
        throw psc::Error(psc::ErrorCode::InvalidMesh,
                         name + ": face " + std::to_string(f) + " refers to a node outside m_nodes");
      triangles[static_cast<std::size_t>(f)][static_cast<std::size_t>(k)] = static_cast<psc::Index>(node);
    }
  }
  return triangles;
}

double marginOf(const btSoftBody& body) { return body.getCollisionShape()->getMargin(); }

std::string nameOf(const btSoftBody& body) {
  return "btSoftBody #" + std::to_string(body.getWorldArrayIndex());
}

bool nodesFinite(const btSoftBody& body) {
  for (int i = 0; i < body.m_nodes.size(); ++i) {
    const btSoftBody::Node& n = body.m_nodes[i];
    if (!std::isfinite(n.m_x.x()) || !std::isfinite(n.m_x.y()) || !std::isfinite(n.m_x.z()) ||
        !std::isfinite(n.m_q.x()) || !std::isfinite(n.m_q.y()) || !std::isfinite(n.m_q.z()))
      return false;
  }
  return true;
}

void countRejected(const std::string& message, SyncCounters& counters) {
  ++counters.skipped;
  if (counters.first_rejection.empty()) counters.first_rejection = message;
}

}  // namespace

BodyRegistry::Fingerprint BodyRegistry::fingerprintOf(const btSoftBody& body) {
  Fingerprint print;
  print.node_count = body.m_nodes.size();
  print.nodes = print.node_count > 0 ? static_cast<const void*>(&body.m_nodes[0]) : nullptr;
  print.face_count = body.m_faces.size();
  print.faces = print.face_count > 0 ? static_cast<const void*>(&body.m_faces[0]) : nullptr;
  if (print.face_count > 0 && print.node_count > 0) {
    const auto base = reinterpret_cast<std::uintptr_t>(&body.m_nodes[0]);
    std::uint64_t h = 1469598103934665603ull;  // FNV-1a over the sampled faces' node offsets
    const int samples = std::min(16, print.face_count);
    for (int s = 0; s < samples; ++s) {
      const btSoftBody::Face& f = body.m_faces[static_cast<int>(std::int64_t{s} * print.face_count / samples)];
      for (const btSoftBody::Node* n : f.m_n) {
        h ^= static_cast<std::uint64_t>(reinterpret_cast<std::uintptr_t>(n) - base);
        h *= 1099511628211ull;
      }
    }
    print.topology = h;
  }
  const btBroadphaseProxy* proxy = body.getBroadphaseHandle();
  print.proxy = proxy;
  print.proxy_id = proxy != nullptr ? proxy->getUid() : -1;
  return print;
}

void BodyRegistry::sync(const btAlignedObjectArray<btSoftBody*>& world_bodies, const Participates& participates,
                        psc::SensorWorld& sensors, SyncCounters& counters, std::vector<const btSoftBody*>& left) {
  for (auto& entry : records_) entry.second.seen = false;
  std::unordered_set<const btSoftBody*> now;
  now.reserve(static_cast<std::size_t>(world_bodies.size()));
  for (int i = 0; i < world_bodies.size(); ++i) {
    btSoftBody* body = world_bodies[i];
    if (body == nullptr || !now.insert(body).second) continue;
    auto it = records_.find(body);
    if (!participates(*body)) {
      if (it != records_.end()) {
        if (it->second.id != psc::kInvalidBody) sensors.removeBody(it->second.id);
        records_.erase(it);
      }
      continue;
    }
    if (it == records_.end()) {
      it = records_.emplace(body, Record{}).first;
      dirty_.erase(body);
      add(*body, it->second, sensors, counters);
    } else {
      update(*body, it->second, sensors, counters);
    }
    it->second.seen = true;
  }
  // Bodies that left the world: their memory may be gone, so only their ids are used.
  for (auto it = records_.begin(); it != records_.end();) {
    if (it->second.seen) {
      ++it;
      continue;
    }
    if (it->second.id != psc::kInvalidBody) sensors.removeBody(it->second.id);
    it = records_.erase(it);
  }
  bodies_.clear();
  for (int i = 0; i < world_bodies.size(); ++i) {
    const auto it = records_.find(world_bodies[i]);
    if (it != records_.end() && it->second.id != psc::kInvalidBody) bodies_[it->second.id] = world_bodies[i];
  }
  for (const btSoftBody* body : present_) {
    if (now.count(body) == 0) {
      left.push_back(body);
      dirty_.erase(body);
    }
  }
  present_ = std::move(now);
}

void BodyRegistry::add(btSoftBody& body, Record& record, psc::SensorWorld& sensors, SyncCounters& counters) {
  record.print = fingerprintOf(body);
  record.margin = marginOf(body);
  record.id = psc::kInvalidBody;
  record.rejection.clear();
  record.nonfinite = false;
  try {
    psc::BodyDesc desc;
    desc.name = nameOf(body);
    desc.triangles = trianglesOf(body, desc.name);
    desc.positions = nodeView(body, false);
    desc.previous = nodeView(body, true);
    desc.margin = record.margin;
    record.id = sensors.addBody(desc);
    ++counters.bodies;
  } catch (const psc::Error& error) {
    record.rejection = error.what();
    countRejected(record.rejection, counters);
  }
}

void BodyRegistry::update(btSoftBody& body, Record& record, psc::SensorWorld& sensors, SyncCounters& counters) {
  const Fingerprint print = fingerprintOf(body);
  const bool dirty = dirty_.erase(&body) > 0;
  if (!print.sameBody(record.print)) {
    // Removed and re-added, or another body at a recycled address: start afresh.
    if (record.id != psc::kInvalidBody) sensors.removeBody(record.id);
    add(body, record, sensors, counters);
    return;
  }
  if (record.id == psc::kInvalidBody) {
    // A margin set anew may be a valid one again (a review's finding, stop 46: a body rejected for a
    // negative margin stayed out after it was set back).
    const bool changed = dirty || !print.sameMesh(record.print) || print.nodes != record.print.nodes ||
                         marginOf(body) != record.margin || (record.nonfinite && nodesFinite(body));
    if (changed) {
      add(body, record, sensors, counters);
    } else {
      countRejected(record.rejection, counters);
    }
    return;
  }
  try {
    const std::string name = nameOf(body);
    if (dirty || !print.sameMesh(record.print)) {
      // First: it throws for a body left without nodes or faces, before m_nodes[0] is touched.
      std::vector<psc::Triangle> triangles = trianglesOf(body, name);
      sensors.replaceMesh(record.id, std::move(triangles), nodeView(body, false), nodeView(body, true));
    } else if (print.nodes != record.print.nodes) {
      sensors.setPositions(record.id, nodeView(body, false), nodeView(body, true));
    }
    record.print = print;
    const double margin = marginOf(body);
    if (margin != record.margin) {
      sensors.setMargin(record.id, margin);
      record.margin = margin;
    }
    ++counters.bodies;
  } catch (const psc::Error& error) {
    if (sensors.hasBody(record.id)) sensors.removeBody(record.id);
    record.id = psc::kInvalidBody;
    record.print = print;
    record.margin = marginOf(body);  // the margin it was rejected with: another one is offered again
    record.rejection = error.what();
    countRejected(record.rejection, counters);
  }
}

bool BodyRegistry::reject(psc::BodyId id, const std::string& message, psc::SensorWorld& sensors,
                          SyncCounters& counters) {
  const auto it = bodies_.find(id);
  if (it == bodies_.end()) return false;
  const auto rec = records_.find(it->second);
  if (rec == records_.end() || rec->second.id != id) return false;
  if (sensors.hasBody(id)) sensors.removeBody(id);
  bodies_.erase(it);
  rec->second.id = psc::kInvalidBody;
  rec->second.rejection = message;
  rec->second.nonfinite = true;
  if (counters.bodies > 0) --counters.bodies;
  countRejected(message, counters);
  return true;
}

std::optional<psc::BodyId> BodyRegistry::idOf(const btSoftBody* body) const {
  const auto it = records_.find(body);
  if (it == records_.end() || it->second.id == psc::kInvalidBody) return std::nullopt;
  return it->second.id;
}

std::optional<psc::BodyId> BodyRegistry::currentIdOf(const btSoftBody& body) const {
  const auto it = records_.find(&body);
  if (it == records_.end() || it->second.id == psc::kInvalidBody || dirty_.count(&body) != 0) return std::nullopt;
  if (!fingerprintOf(body).same(it->second.print)) return std::nullopt;
  return it->second.id;
}

btSoftBody* BodyRegistry::bodyOf(psc::BodyId id) const {
  const auto it = bodies_.find(id);
  return it == bodies_.end() ? nullptr : it->second;
}

}  // namespace psc::bullet::detail
