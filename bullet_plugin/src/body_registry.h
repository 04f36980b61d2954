// Private: keeps the sensor world's bodies in line with the soft bodies of a Bullet world.
#pragma once

#include "psc/world.h"

#include <BulletSoftBody/btSoftBody.h>

#include <cstdint>
#include <functional>
#include <optional>
#include <string>
#include <unordered_map>
#include <unordered_set>
#include <vector>

namespace psc::bullet::detail {

struct SyncCounters {
  std::size_t bodies = 0;          ///< participating bodies the sensor world holds after the sync
  std::size_t skipped = 0;         ///< participating bodies the core does not hold (no faces, rejected)
  std::string first_rejection;     ///< the core's message for the first rejected body, if any
};

/// Each sync compares the world's soft body array with what the sensor world holds. A body is
/// identified by its address plus a fingerprint (m_nodes / m_faces buffers and sizes, broadphase
/// proxy and its id), so a body deleted and another allocated at the same address is not
/// mistaken for the old one. The registry never dereferences a body that is not in the array it
/// is given: bodies removed from the world (and maybe deleted) are only forgotten.
class BodyRegistry {
 public:
  using Participates = std::function<bool(const btSoftBody&)>;

  /// Adds, updates and removes sensor bodies. Bodies that were in the world at the previous sync
  /// and are not any more are appended to `left`.
  void sync(const btAlignedObjectArray<btSoftBody*>& world_bodies, const Participates& participates,
            psc::SensorWorld& sensors, SyncCounters& counters, std::vector<const btSoftBody*>& left);

  std::optional<psc::BodyId> idOf(const btSoftBody* body) const;
  /// The body's id when the sensor world's view of it is still current (same proxy, node and face
  /// buffers and counts as at the last sync, not marked dirty): what the next sync would leave as
  /// it is. Nothing otherwise.
  std::optional<psc::BodyId> currentIdOf(const btSoftBody& body) const;
  /// The body behind a sensor id, as of the last sync (valid until the world's bodies change).
  btSoftBody* bodyOf(psc::BodyId id) const;
  /// Re-read the body's triangles at the next sync.
  void markDirty(const btSoftBody* body) { dirty_.insert(body); }
  /// Takes out of the sensor world a body whose input the core could not step (psc::Error::body():
  /// non-finite nodes, say), with the core's message: it is then left out like a rejected body, and
  /// offered again at a sync that finds all its nodes finite (or its mesh changed). False when no
  /// registered body has that id.
  bool reject(psc::BodyId id, const std::string& message, psc::SensorWorld& sensors, SyncCounters& counters);

 private:
  struct Fingerprint {
    const void* nodes = nullptr;
    int node_count = 0;
    const void* faces = nullptr;
    int face_count = 0;
    const void* proxy = nullptr;
    int proxy_id = 0;
    /// The node indices of up to 16 faces spread over the array, hashed: broadphases that recycle
    /// proxies (btAxisSweep3, btSimpleBroadphase) give a body deleted and another added in its
    /// place the same proxy and uid, and the new one often the same address, buffers and counts;
    /// its triangles then differ here (a review's finding: a respawned grid cloth of the other
    /// diagonal kept the old triangles).
    std::uint64_t topology = 0;
    bool sameBody(const Fingerprint& o) const { return proxy == o.proxy && proxy_id == o.proxy_id; }
    bool sameMesh(const Fingerprint& o) const {
      return node_count == o.node_count && faces == o.faces && face_count == o.face_count && topology == o.topology;
    }
    bool same(const Fingerprint& o) const { return sameBody(o) && sameMesh(o) && nodes == o.nodes; }
  };
  struct Record {
    Fingerprint print;
    psc::BodyId id = psc::kInvalidBody;  ///< kInvalidBody: participating but rejected by the core
    double margin = 0.0;
    std::string rejection;  ///< the core's message when id is kInvalidBody
    bool nonfinite = false;  ///< rejected during a step (reject()): offered again once its nodes are finite
    bool seen = false;
  };

  static Fingerprint fingerprintOf(const btSoftBody& body);
  /// Adds the body; on rejection stores the message and keeps the record with kInvalidBody so the
  /// same mesh is not offered again every step.
  void add(btSoftBody& body, Record& record, psc::SensorWorld& sensors, SyncCounters& counters);
  void update(btSoftBody& body, Record& record, psc::SensorWorld& sensors, SyncCounters& counters);

  std::unordered_map<const btSoftBody*, Record> records_;  ///< participating bodies only
  std::unordered_map<psc::BodyId, btSoftBody*> bodies_;    ///< rebuilt at each sync
  std::unordered_set<const btSoftBody*> present_;          ///< all soft bodies at the previous sync
  std::unordered_set<const btSoftBody*> dirty_;
  std::size_t names_ = 0;
};

}  // namespace psc::bullet::detail
