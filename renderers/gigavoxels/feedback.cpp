/// @file feedback.cpp
/// @brief Ray recording's slow paths, buffer clearing and the two-pass compaction.

#include "renderers/gigavoxels/feedback.h"

#include <algorithm>
#include <array>
#include <bit>

#include <fmt/format.h>

#include "core/error.h"
#include "core/parallel.h"

namespace brickyard::gigavoxels {

namespace {

/// Spilled share buffers of the recorders on this thread, reused so that long lists allocate
/// only until the pool has warmed up. A pool rather than one vector: a thread may hold the four
/// recorders of a packet at once.
std::vector<std::unique_ptr<std::vector<uint32_t>>>& spill_pool() {
  thread_local std::vector<std::unique_ptr<std::vector<uint32_t>>> pool;
  return pool;
}

/// Whether v is among a[0, n). No early exit: the loop vectorises, and n is at most 64.
inline bool contains(const uint32_t* a, size_t n, uint32_t v) {
  unsigned hit = 0;
  for (size_t j = 0; j < n; ++j) hit |= unsigned(a[j] == v);
  return hit != 0;
}

void add(CompactionStats& sum, const CompactionStats& part) {
  sum.slots += part.slots;
  sum.empty += part.empty;
  sum.local_duplicates += part.local_duplicates;
  sum.out += part.out;
}

/// Stands in for a missing left or upper neighbour, so that edge packets take the same path:
/// kNoEntry never equals a non-empty slot.
constexpr std::array<uint32_t, 4 * kMaxSlotsPerPixel + 4> kEmptyBlock = [] {
  std::array<uint32_t, 4 * kMaxSlotsPerPixel + 4> block{};
  block.fill(kNoEntry);
  return block;
}();

/// Packets per compaction chunk, the unit of the parallel loops and of the prefix sum. The
/// output never depends on it (the scatter keeps buffer order), nor on the thread count.
constexpr size_t kPacketsPerChunk = 256;

}  // namespace

// --- RayRecorder ----------------------------------------------------------------------

RayRecorder::RayRecorder(uint32_t* use_slots, uint32_t* request_slot, uint32_t slots, uint32_t rank, uint64_t frame)
    : use_slots_(use_slots),
      request_slot_(request_slot),
      frame_(frame),
      slots_(slots),
      share_begin_(rank * slots),
      kept_(inline_) {}

RayRecorder::RayRecorder(RayRecorder&& other) noexcept
    : use_slots_(other.use_slots_),
      request_slot_(other.request_slot_),
      frame_(other.frame_),
      slots_(other.slots_),
      share_begin_(other.share_begin_),
      last_(other.last_),
      request_(other.request_),
      length_(other.length_),
      offset_(other.offset_),
      window_(other.window_),
      dropped_requests_(other.dropped_requests_),
      finished_(other.finished_),
      capacity_(other.capacity_),
      spill_(std::move(other.spill_)) {
  if (spill_) {
    kept_ = spill_->data();
  } else {
    // Only what used() wrote: windows before the current one, and the current one's part.
    const uint32_t in_share = std::min(other.offset_ > share_begin_ ? other.offset_ - share_begin_ : 0, slots_);
    std::copy(other.inline_, other.inline_ + std::min(kInline, window_ * slots_ + in_share), inline_);
    kept_ = inline_;
  }
  other.finished_ = true;  // the moved-from recorder writes nothing
}

RayRecorder::~RayRecorder() {
  if (spill_) spill_pool().push_back(std::move(spill_));
}

void RayRecorder::grow() {
  const size_t capacity = 2 * size_t(capacity_);
  if (!spill_) {
    auto& pool = spill_pool();
    if (pool.empty()) {
      spill_ = std::make_unique<std::vector<uint32_t>>();
    } else {
      spill_ = std::move(pool.back());
      pool.pop_back();
    }
    if (spill_->size() < capacity) spill_->resize(capacity);
    std::copy(inline_, inline_ + capacity_, spill_->data());
  } else if (spill_->size() < capacity) {
    spill_->resize(capacity);
  }
  kept_ = spill_->data();
  capacity_ = uint32_t(spill_->size());
}

uint32_t RayRecorder::window() const {
  // Short lists skip both divisions, and the frame's is a 32-bit one while it fits: finish()
  // runs once per ray, and a 64-bit division is most of its cost.
  if (length_ <= 4 * slots_) return 0;
  const uint32_t windows = (length_ + 4 * slots_ - 1) / (4 * slots_);
  return frame_ >> 32 == 0 ? uint32_t(frame_) % windows : uint32_t(frame_ % windows);
}

void RayRecorder::finish() {
  if (finished_) return;
  finished_ = true;
  const uint32_t w = window();
  const uint32_t first = w * 4 * slots_ + share_begin_;  // sequence index of this share's first entry
  const uint32_t n = length_ > first ? std::min(slots_, length_ - first) : 0;
  // A plain loop: K is a handful, and memmove/memset calls would cost more than the copy.
  const uint32_t* from = kept_ + w * slots_;
  for (uint32_t i = 0; i < slots_; ++i) use_slots_[i] = i < n ? from[i] : kNoEntry;
  *request_slot_ = request_;
}

// --- UseBuffer ------------------------------------------------------------------------

UseBuffer::UseBuffer(int width, int height, int slots_per_pixel)
    : width_(width), height_(height), slots_per_pixel_(slots_per_pixel) {
  if (width < 0 || height < 0)
    throw Error(Errc::invalid_argument, fmt::format("use buffer: image size {}x{} is negative", width, height));
  if (slots_per_pixel < 1 || slots_per_pixel > kMaxSlotsPerPixel)
    throw Error(Errc::invalid_argument,
                fmt::format("use buffer: {} slots per pixel (1..{} supported)", slots_per_pixel, kMaxSlotsPerPixel));
  slots_.assign(packet_count() * block_stride(), kNoEntry);
}

void UseBuffer::begin_frame(uint64_t frame) {
  frame_ = frame;
  uint32_t* data = slots_.data();
  parallel_for<size_t>(0, slots_.size(), size_t(1) << 16,
                       [&](size_t b, size_t e) { std::fill(data + b, data + e, kNoEntry); });
}

// --- Compactor ------------------------------------------------------------------------

CompactionReport Compactor::compact(const UseBuffer& buffer, std::vector<uint32_t>& out_uses,
                                    std::vector<uint32_t>& out_requests) {
  const size_t packets = buffer.packet_count();
  const size_t per_row = size_t(buffer.packets_x());
  const size_t stride = buffer.block_stride();
  const size_t uses = 4 * size_t(buffer.slots_per_pixel());  // use slots per block; requests follow
  const uint32_t* slots = buffer.entries().data();
  const size_t chunks = (packets + kPacketsPerChunk - 1) / kPacketsPerChunk;
  use_keep_.resize(packets);
  request_keep_.resize(packets);
  chunk_reports_.resize(chunks);

  // Step 1: keep flags. A slot survives unless empty or equal to an earlier slot of its block
  // or to any slot of the left or upper neighbour's block, within the same stream.
  parallel_for<size_t>(0, chunks, 1, [&](size_t chunk_begin, size_t chunk_end) {
    for (size_t c = chunk_begin; c < chunk_end; ++c) {
      CompactionReport report;  // local: neighbouring chunks' reports share cache lines
      const size_t p_end = std::min(packets, (c + 1) * kPacketsPerChunk);
      for (size_t p = c * kPacketsPerChunk; p < p_end; ++p) {
        const uint32_t* own = slots + p * stride;
        const uint32_t* left = p % per_row != 0 ? own - stride : kEmptyBlock.data();
        const uint32_t* up = p >= per_row ? own - per_row * stride : kEmptyBlock.data();
        uint64_t use_mask = 0;
        for (size_t i = 0; i < uses; ++i) {
          const uint32_t v = own[i];
          if (v == kNoEntry) {
            ++report.uses.empty;
          } else if (contains(own, i, v) || contains(left, uses, v) || contains(up, uses, v)) {
            ++report.uses.local_duplicates;
          } else {
            use_mask |= uint64_t(1) << i;
            ++report.uses.out;
          }
        }
        uint8_t request_mask = 0;
        for (size_t r = 0; r < 4; ++r) {
          const uint32_t v = own[uses + r];
          if (v == kNoEntry) {
            ++report.requests.empty;
          } else if (contains(own + uses, r, v) || contains(left + uses, 4, v) || contains(up + uses, 4, v)) {
            ++report.requests.local_duplicates;
          } else {
            request_mask |= uint8_t(1u << r);
            ++report.requests.out;
          }
        }
        use_keep_[p] = use_mask;
        request_keep_[p] = request_mask;
      }
      report.uses.slots = (p_end - c * kPacketsPerChunk) * uses;
      report.requests.slots = (p_end - c * kPacketsPerChunk) * 4;
      chunk_reports_[c] = report;
    }
  });

  // Step 2: exclusive prefix sum of the chunks' kept counts (a few hundred chunks: serial).
  // Summed in chunk order, so the totals are the same whatever the thread count.
  chunk_use_offset_.resize(chunks);
  chunk_request_offset_.resize(chunks);
  CompactionReport total;
  for (size_t c = 0; c < chunks; ++c) {
    chunk_use_offset_[c] = total.uses.out;
    chunk_request_offset_[c] = total.requests.out;
    add(total.uses, chunk_reports_[c].uses);
    add(total.requests, chunk_reports_[c].requests);
  }
  out_uses.resize(total.uses.out);
  out_requests.resize(total.requests.out);

  // Step 3: scatter the kept slots, in buffer order.
  parallel_for<size_t>(0, chunks, 1, [&](size_t chunk_begin, size_t chunk_end) {
    for (size_t c = chunk_begin; c < chunk_end; ++c) {
      uint32_t* to_use = out_uses.data() + chunk_use_offset_[c];
      uint32_t* to_request = out_requests.data() + chunk_request_offset_[c];
      const size_t p_end = std::min(packets, (c + 1) * kPacketsPerChunk);
      for (size_t p = c * kPacketsPerChunk; p < p_end; ++p) {
        const uint32_t* own = slots + p * stride;
        for (uint64_t m = use_keep_[p]; m != 0; m &= m - 1) *to_use++ = own[std::countr_zero(m)];
        for (unsigned m = request_keep_[p]; m != 0; m &= m - 1)
          *to_request++ = own[uses + size_t(std::countr_zero(m))];
      }
    }
  });
  return total;
}

}  // namespace brickyard::gigavoxels
