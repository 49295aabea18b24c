#pragma once
/// @file render.h
/// @brief The frame driver: one frame of a back end, its tiles in parallel (TBB). Opening a
/// dataset and building its cache and back end is the session's (session/render_session.h).

#include "renderers/common/renderer.h"

namespace brickyard {

inline constexpr int kTileSize = 16;

/// @brief Renders one frame with `renderer`: pages.frame_begin(), begin_frame(), tiles in
/// parallel (TBB), end_frame() (and further passes while another_pass()), pages.frame_end().
/// Fills `out` (allocated here) and returns the frame's statistics.
FrameStats render_frame(Renderer& renderer, const RenderContext& context, const FrameSetup& setup, FrameBuffers& out);

}  // namespace brickyard
