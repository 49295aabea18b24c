#include "cache/policy.h"

#include <fmt/format.h>

#include "cache/policies/policies.h"
#include "core/error.h"

namespace brickyard {
namespace {

struct Entry {
  const char* name;
  const char* description;
  std::unique_ptr<Policy> (*make)(uint64_t capacity);
};

// Explicit registration: adding a policy is one line here.
const Entry kPolicies[] = {
    {"lru", "least recently used", policy_detail::make_lru},
    {"clock", "CLOCK / second chance: a reference bit per entry and a sweeping hand", policy_detail::make_clock},
    {"arc", "adaptive replacement cache: recency and frequency lists with ghosts", policy_detail::make_arc},
    {"s3fifo", "S3-FIFO: small, main and ghost FIFO queues", policy_detail::make_s3fifo},
    {"sieve", "SIEVE: FIFO with visited bits and a lazy hand", policy_detail::make_sieve},
    {"lru-frame", "LRU with per-frame timestamps: entries used this frame are never evicted (GigaVoxels)",
     policy_detail::make_lru_frame},
    {"opt", "Belady's optimum: evicts the furthest next use (offline replay only)", policy_detail::make_opt},
};

}  // namespace

std::vector<PolicyInfo> policy_catalog() {
  std::vector<PolicyInfo> out;
  for (const auto& e : kPolicies) out.push_back({e.name, e.description});
  return out;
}

std::vector<std::string> policy_names() {
  std::vector<std::string> out;
  for (const auto& e : kPolicies) out.emplace_back(e.name);
  return out;
}

std::unique_ptr<Policy> make_policy(std::string_view name, uint64_t capacity) {
  for (const auto& e : kPolicies)
    if (name == e.name) return e.make(capacity);
  throw Error(Errc::invalid_argument, fmt::format("unknown cache policy '{}' (known policies: {})", name,
                                                  fmt::join(policy_names(), ", ")))
      .with_field("policy");
}

}  // namespace brickyard
