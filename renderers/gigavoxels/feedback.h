#pragma once
/// @file feedback.h
/// @brief The `gigavoxels` back end's ray-guided feedback: per-pixel lists of the nodes each ray
/// used and the one subdivision or data request it made, shared within 2x2 packets and cycled
/// through a temporal window, and the compaction that turns a frame's lists into the short
/// streams the loader reads (Crassin et al., GigaVoxels, "usage buffer" and request lists).
///
/// Entries. Opaque 32-bit values chosen by the renderer (node-pool addresses with its own tags);
/// kNoEntry marks an empty slot and is ignored when a ray reports it. Nothing here interprets an
/// entry beyond equality.
///
/// Layout. Pixels are grouped in 2x2 packets, row-major; a packet at the right or bottom edge of
/// an odd-sized image is partial and its missing rays' slots stay empty. Each packet owns one
/// contiguous block: 4K use slots (K per ray) followed by 4 request slots (one per ray). The ray
/// of rank r = (x & 1) + 2 (y & 1) writes use slots [rK, (r+1)K) and request slot r.
///
/// Spatial pattern. Neighbouring rays traverse nearly the same nodes, so instead of each ray
/// keeping its first K nodes, rank r keeps the nodes of sequence index [rK, (r+1)K) of its own
/// list (within the window below): together the packet covers 4K consecutive nodes of its path.
///
/// Temporal window. A ray whose list has L > 4K distinct-consecutive entries keeps window
/// w = frame mod ceil(L / 4K), i.e. sequence indices [w 4K + rK, w 4K + (r+1)K): over
/// ceil(L / 4K) consecutive frames every part of its share is kept once. Short lists use window 0
/// every frame.
///
/// Concurrency and lifetime. begin_frame() is not thread-safe with anything else. Between
/// begin_frame() calls, any number of threads may call recorder() and record rays at once, under
/// one contract: at most one RayRecorder per pixel and frame (one ray per pixel). Rays of
/// different pixels write disjoint slots, so neither locks nor atomics are needed; a recorder
/// itself belongs to one thread. Compaction reads the buffer after all recorders have finished
/// (the renderer's parallel loop joins first). A RayRecorder must not outlive the frame.

#include <cstdint>
#include <memory>
#include <span>
#include <vector>

#include "core/pool_memory.h"

namespace brickyard::gigavoxels {

/// @brief The empty slot; UseBuffer::begin_frame() fills every slot with it.
inline constexpr uint32_t kNoEntry = 0xffffffffu;

/// @brief Largest slots_per_pixel: a packet's 4K use slots then fit one 64-bit keep mask.
inline constexpr int kMaxSlotsPerPixel = 16;

class UseBuffer;

/// @brief Records one ray's node uses and its request, then writes its share into the packet's
/// slots at finish(). Not thread-safe; cheap to create. It buffers only its own rank's part of
/// every window (L / 4 entries), inline up to 64 (lists up to 256 nodes with K = 4), beyond that
/// in a vector taken from a per-thread pool and given back on destruction: no allocation per ray
/// once the pool is warm.
class RayRecorder {
 public:
  RayRecorder(RayRecorder&& other) noexcept;
  RayRecorder(const RayRecorder&) = delete;
  RayRecorder& operator=(const RayRecorder&) = delete;
  RayRecorder& operator=(RayRecorder&&) = delete;
  ~RayRecorder();

  /// @brief The ray used this node; call front to back. An entry equal to the previous one (or
  /// kNoEntry) is ignored, so a ray may report the node of every sample.
  void used(uint32_t entry) {
    if (entry == last_ || entry == kNoEntry) return;
    last_ = entry;
    // Keep only this rank's part of each window; sequence index = window_ * 4K + offset_.
    const uint32_t in_share = offset_ - share_begin_;
    if (in_share < slots_) {
      const uint32_t at = window_ * slots_ + in_share;
      if (at >= capacity_) grow();
      kept_[at] = entry;
    }
    ++length_;
    if (++offset_ == 4 * slots_) {
      offset_ = 0;
      ++window_;
    }
  }

  /// @brief The ray's subdivision or data request. Only the first (front-most) is kept; later
  /// ones are counted and dropped, and the ray makes them again in a later frame.
  void request(uint32_t entry) {
    if (entry == kNoEntry) return;
    if (request_ == kNoEntry)
      request_ = entry;
    else
      ++dropped_requests_;
  }

  /// @brief Writes the ray's share of the chosen window and its request into the buffer. Later
  /// calls do nothing; a recorder destroyed without finish() leaves its slots empty.
  void finish();

  /// @brief Distinct-consecutive entries reported so far (L).
  uint32_t length() const { return length_; }
  /// @brief The window finish() keeps: frame mod ceil(L / 4K), 0 for L <= 4K.
  uint32_t window() const;
  /// @brief Requests dropped because an earlier one was kept.
  uint32_t dropped_requests() const { return dropped_requests_; }

 private:
  friend class UseBuffer;
  static constexpr uint32_t kInline = 64;

  RayRecorder(uint32_t* use_slots, uint32_t* request_slot, uint32_t slots, uint32_t rank, uint64_t frame);
  void grow();  // moves kept_ from the inline array to (a larger) pooled vector

  uint32_t* use_slots_;     // the K use slots of this ray in its packet
  uint32_t* request_slot_;  // its request slot
  uint64_t frame_;
  uint32_t slots_;        // K
  uint32_t share_begin_;  // rank * K
  uint32_t last_ = kNoEntry, request_ = kNoEntry;
  uint32_t length_ = 0, offset_ = 0, window_ = 0, dropped_requests_ = 0;
  bool finished_ = false;
  uint32_t* kept_;  // this rank's part of window w at [w K, (w+1) K)
  uint32_t capacity_ = kInline;
  std::unique_ptr<std::vector<uint32_t>> spill_;  // from a per-thread pool, returned on destruction
  uint32_t inline_[kInline];
};

/// @brief One frame's per-pixel feedback lists (see the file comment for layout and contract).
class UseBuffer {
 public:
  /// @brief An empty buffer for a width x height image, slots_per_pixel K in [1, 16]; throws
  /// Error(Errc::invalid_argument) otherwise.
  UseBuffer(int width, int height, int slots_per_pixel = 4);

  /// @brief Empties every slot (in parallel) and sets the frame number the windows follow.
  void begin_frame(uint64_t frame);

  /// @brief The recorder of the ray through pixel (x, y); see the concurrency contract.
  RayRecorder recorder(int x, int y) {
    const size_t block = packet_of(x, y) * block_stride();
    const uint32_t rank = rank_of(x, y);
    return RayRecorder(&slots_[block + rank * slots_per_pixel_], &slots_[block + 4 * slots_per_pixel_ + rank],
                       uint32_t(slots_per_pixel_), rank, frame_);
  }

  int width() const { return width_; }
  int height() const { return height_; }
  int slots_per_pixel() const { return slots_per_pixel_; }
  uint64_t frame() const { return frame_; }
  int packets_x() const { return (width_ + 1) / 2; }
  int packets_y() const { return (height_ + 1) / 2; }
  size_t packet_count() const { return size_t(packets_x()) * size_t(packets_y()); }
  /// @brief Slots per packet block: 4K uses, then 4 requests.
  size_t block_stride() const { return 4 * size_t(slots_per_pixel_) + 4; }

  size_t packet_of(int x, int y) const { return size_t(y / 2) * size_t(packets_x()) + size_t(x / 2); }
  static uint32_t rank_of(int x, int y) { return uint32_t(x & 1) + 2 * uint32_t(y & 1); }

  /// @brief The whole buffer, packet blocks in row-major packet order.
  std::span<const uint32_t> entries() const { return slots_; }
  /// @brief A packet's 4K use slots, rank r's at [rK, (r+1)K).
  std::span<const uint32_t> use_slots(size_t packet) const {
    return std::span<const uint32_t>(slots_).subspan(packet * block_stride(), 4 * size_t(slots_per_pixel_));
  }
  /// @brief A packet's 4 request slots, one per rank.
  std::span<const uint32_t> request_slots(size_t packet) const {
    return std::span<const uint32_t>(slots_).subspan(packet * block_stride() + 4 * size_t(slots_per_pixel_), 4);
  }

 private:
  int width_, height_, slots_per_pixel_;
  uint64_t frame_ = 0;
  std::vector<uint32_t, PoolAllocator<uint32_t>> slots_;
};

/// @brief What compaction did to one stream: slots = empty + local_duplicates + out.
struct CompactionStats {
  uint64_t slots = 0, empty = 0, local_duplicates = 0, out = 0;
  CompactionStats& operator+=(const CompactionStats& o) {
    slots += o.slots, empty += o.empty, local_duplicates += o.local_duplicates, out += o.out;
    return *this;
  }
};

/// @brief Both streams: the use list and the request list.
struct CompactionReport {
  CompactionStats uses, requests;
  CompactionReport& operator+=(const CompactionReport& o) {
    uses += o.uses, requests += o.requests;
    return *this;
  }
};

/// @brief Compacts a frame's UseBuffer into the unique-ish lists the loader reads, keeping its
/// scratch between frames.
///
/// Step 1, neighbour-local duplicate removal, per stream (uses and requests never mix, so a
/// request is only ever removed as a duplicate of an equal request): a non-empty slot is kept
/// unless an earlier slot of its packet, or any slot of the packet to its left or the packet
/// above, holds the same value. Every slot's decision reads only those three blocks, so the pass
/// is data-parallel with bounded work. Nothing the buffer holds is lost: of the packets holding
/// a value, the first in row-major order has neither its left nor its upper neighbour holding
/// it, so it keeps its first occurrence. (The paper's pass looks at the left neighbour only;
/// looking up as well reduces a uniform region to one copy instead of one per packet row.)
/// Steps 2 and 3, stream compaction: per fixed chunk of packets the kept counts, an exclusive
/// prefix sum over the chunks, then a parallel scatter that preserves slot order.
///
/// The output may still hold a value several times (packets far apart that used the same node):
/// the loader's marks are idempotent, and it keeps the bricks it asked for in a set of its own
/// (one request per node), so removing those here would cost a hash or a sort for nothing.
/// The result does not depend on the thread count. Not thread-safe: one compaction at a time.
class Compactor {
 public:
  /// @brief Replaces out_uses and out_requests by the kept entries in buffer order.
  CompactionReport compact(const UseBuffer& buffer, std::vector<uint32_t>& out_uses,
                           std::vector<uint32_t>& out_requests);

 private:
  std::vector<uint64_t> use_keep_;     // per packet: bit i keeps use slot i
  std::vector<uint8_t> request_keep_;  // per packet: bit r keeps request slot r
  std::vector<CompactionReport> chunk_reports_;
  std::vector<uint64_t> chunk_use_offset_, chunk_request_offset_;  // exclusive prefix sums
};

}  // namespace brickyard::gigavoxels
