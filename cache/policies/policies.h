#pragma once
// Factories of the policies, for the registry in cache/policy.cpp only.

#include <memory>

#include "cache/policy.h"

namespace brickyard::policy_detail {

std::unique_ptr<Policy> make_lru(uint64_t capacity);
std::unique_ptr<Policy> make_lru_frame(uint64_t capacity);
std::unique_ptr<Policy> make_clock(uint64_t capacity);
std::unique_ptr<Policy> make_arc(uint64_t capacity);
std::unique_ptr<Policy> make_s3fifo(uint64_t capacity);
std::unique_ptr<Policy> make_sieve(uint64_t capacity);
std::unique_ptr<Policy> make_opt(uint64_t capacity);

}  // namespace brickyard::policy_detail
