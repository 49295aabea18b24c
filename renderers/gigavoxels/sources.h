#pragma once
/// @file sources.h
/// @brief Where the `gigavoxels` back end's bricks come from: the store through the cache, the
/// store amplified below its finest level by procedural noise (procedural.h), or a producer
/// alone (the Menger sponge). The loader (frame.cpp) asks its Source to classify nodes and to
/// fill bricks; nothing else in the back end reads the store.
///
/// Thread safety: classify(), fill() and the budget are the loader's, called on one thread
/// between passes; arity(), brick_size() and max_depth() never change, and any thread reads them.

#include <cstdint>
#include <memory>
#include <span>

#include "renderers/common/renderer.h"
#include "renderers/gigavoxels/procedural.h"

namespace brickyard::gigavoxels {

struct GigaVoxelsParams;

/// The amplified store's coarse sampler reads stored bricks through the cache's L1 beside the
/// loader's staged ones: the slots kept for it.
inline constexpr uint32_t kCoarseSamplerSlots = 64;

/// @brief Where bricks come from: the store through the cache, or a procedural producer.
class Source {
 public:
  virtual ~Source() = default;
  virtual int arity() const = 0;
  virtual int brick_size() const = 0;
  virtual int max_depth() const = 0;
  virtual NodeContent classify(const NodeAddress& a) const = 0;
  /// What fill() did: wrote the values; found the data missing and asked the store for it (or
  /// joined a request already made: it arrives in a later pass); found it missing past the
  /// request budget (asked for in a later pass); or found that it cannot be read (a blocking
  /// fill throws the load's error instead: exact mode stops at a corrupt brick, naming it).
  enum class Fill { filled, requested, missing, failed };
  /// Writes the node's (M + 2)^3 values if the data is resident. With wait, blocks until it is.
  virtual Fill fill(const NodeAddress& a, float* out, bool wait, float priority) = 0;
  /// Reads the bricks of these nodes into the cache side by side, on the threads the pass
  /// leaves idle, ahead of the blocking fills that copy them: a blocking fill reads its brick
  /// on the loader's one thread, and an exact pass asks for hundreds. A hint: what the fills
  /// then return is the same.
  virtual void read_ahead(std::span<const NodeAddress> nodes) { (void)nodes; }
  /// Bricks shared by many nodes (instancing): an id, or 0 for a brick of its own.
  virtual uint64_t shared_id(const NodeAddress& a) const { (void)a; return 0; }
  /// Bricks computed so far, and bricks read from the store.
  virtual uint64_t produced() const { return 0; }
  virtual uint64_t loaded() const { return 0; }
  /// How many missing bricks fill() may ask the store for until the next call, new requests and
  /// renewals alike: it bounds the loads outstanding. Lookups that hit are not limited: a hit
  /// is copied at once and adds nothing to the cache's L1. Requests are, to at most half the
  /// L1 stages (at least one): a pass's loads must fit beside the last pass's until both are
  /// copied, or they push each other out first (and are loaded again).
  virtual void set_request_budget(uint32_t requests) { (void)requests; }
};

/// @brief The source p.source names (0 the store, 1 the Menger sponge, 2 the store amplified),
/// reading a store's bricks as the type it holds.
std::unique_ptr<Source> make_source(const RenderContext& ctx, const GigaVoxelsParams& p);

}  // namespace brickyard::gigavoxels
