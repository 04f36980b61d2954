// Where Bullet's arrays start in memory, and why the midphase cares.
//
// Bullet 3.24 takes every btAlignedObjectArray's block through btAlignedAlloc with a 16-byte
// alignment. On Linux its default allocator puts the block 16 bytes past a malloc'd address, so a
// large array starts 32 bytes into a 64-byte cache line. A btSoftBody::Node is 256 bytes with m_x
// at offset 16 and m_q at 32: in such an array m_x ends one cache line and m_q begins the next, in
// every node. The sensors' refit reads exactly these two vectors of every node every step, so it
// fetches two lines a node where one would do (and so does any loop that reads m_x with m_q or m_v).
//
// alignLargeBulletBlocks() installs an allocator of the same block layout as Bullet's default
// (the malloc'd address stored just before the block, the block zeroed) that aligns every block of
// 4 KiB or more to 64 bytes; smaller blocks keep the alignment Bullet asks for. Since the layouts
// are the same, a block made by either allocator is freed correctly by the other: it may be called
// at any time, but only nodes allocated after it (bodies created later, arrays that grow later)
// gain from it, so call it at start-up, before creating soft bodies.
//
// It is process-wide (Bullet keeps one allocator): do not call it while other threads use Bullet,
// and not if your program installs an allocator of its own with btAlignedAllocSetCustom or
// btAlignedAllocSetCustomAligned (it would replace yours and allocate with malloc). The midphase's
// results do not depend on it, only its speed (docs/BULLET.md, "Node arrays on cache lines").
#pragma once

#include <cstddef>

namespace psc::bullet {

/// Blocks of at least this many bytes get a 64-byte alignment from alignLargeBulletBlocks().
inline constexpr std::size_t kLineAlignedBlockBytes = 4096;

/// Installs the line-aligning allocator (see above). Idempotent.
void alignLargeBulletBlocks();

/// Puts Bullet's default aligned allocator back. Blocks made meanwhile stay valid.
void restoreBulletBlockAlignment();

/// Whether alignLargeBulletBlocks() is in effect (set by this library, not read from Bullet).
bool largeBulletBlocksAligned();

}  // namespace psc::bullet
