#include "psc/bullet/memory.h"

#include <LinearMath/btAlignedAllocator.h>

#include <atomic>
#include <cstdint>
#include <cstdlib>
#include <cstring>

namespace psc::bullet {
namespace {

std::atomic<bool> g_aligned{false};

// The layout of Bullet 3.24's default (btAlignedAllocDefault on Linux): the address malloc gave
// stored in the pointer-sized slot just before the returned block, the block zeroed. Only the
// alignment differs, so either allocator's free takes the other's blocks.
void* lineAlignedAlloc(std::size_t size, int alignment) {
  std::size_t align = alignment > 0 ? static_cast<std::size_t>(alignment) : alignof(void*);
  if (size >= kLineAlignedBlockBytes && align < 64) align = 64;
  const std::size_t extra = sizeof(void*) + align - 1;
  if (size > SIZE_MAX - extra) return nullptr;
  char* real = static_cast<char*>(std::malloc(size + extra));
  if (real == nullptr) return nullptr;
  const std::uintptr_t first = reinterpret_cast<std::uintptr_t>(real + sizeof(void*));
  char* block = real + sizeof(void*) + ((align - first % align) % align);
  std::memcpy(block - sizeof(void*), &real, sizeof(void*));
  std::memset(block, 0, size);
  return block;
}

void lineAlignedFree(void* block) {
  if (block == nullptr) return;
  void* real = nullptr;
  std::memcpy(&real, static_cast<char*>(block) - sizeof(void*), sizeof(void*));
  std::free(real);
}

}  // namespace

void alignLargeBulletBlocks() {
  btAlignedAllocSetCustomAligned(lineAlignedAlloc, lineAlignedFree);
  g_aligned = true;
}

void restoreBulletBlockAlignment() {
  btAlignedAllocSetCustomAligned(nullptr, nullptr);  // Bullet's default
  g_aligned = false;
}

bool largeBulletBlocksAligned() { return g_aligned; }

}  // namespace psc::bullet
