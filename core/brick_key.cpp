#include "core/brick_key.h"

#include <fmt/format.h>

namespace brickyard {

std::string BrickKey::to_string() const { return fmt::format("L{} ({}, {}, {})", level, x, y, z); }

}  // namespace brickyard
