#pragma once
/// @file tets.h
/// @brief The reference renderer's tetrahedral half: the truth every tetrahedral back end's
/// error is measured against (renderers/reference/tets.cpp).

#include <memory>

#include "renderers/common/renderer.h"

namespace brickyard {

/// @brief The reference for a tetrahedral dataset (iso, dvr, mip; shadows; clip box).
std::unique_ptr<Renderer> make_tet_reference(const RenderContext& ctx);

}  // namespace brickyard
