#pragma once
// The shared suites (stability, costs-nothing, match-the-reference, thread counts) run over
// every registered back end that accepts the scene: the registry is the list, so a back end is
// covered the day it registers. These helpers choose the back ends and render a frame the way
// `brickyard render` shows a still: settled first (asynchronous back ends refine over frames as
// their data arrives; their warm-up frames are completed at once where they can).

#include <algorithm>
#include <string>
#include <vector>

#include "session/render_session.h"

namespace brickyard::testing {

/// Every registered back end that renders `mode` on datasets of `kind`, the reference included.
inline std::vector<std::string> backends_for(RenderMode mode, DataKind kind = DataKind::structured) {
  std::vector<std::string> names;
  for (const BackendEntry& e : backends().entries())
    if (e.info.accepts(kind, mode)) names.push_back(e.info.name);
  return names;
}

/// Whether a back end computes the normals the scene asks for, and shadows if it asks for them.
inline bool shades_as_asked(const std::string& backend, const Shading& shading) {
  const BackendInfo& info = backends().find(backend).info;
  if (shading.casts_shadows() && !info.shadows) return false;
  return std::find(info.normals.begin(), info.normals.end(), shading.normals) != info.normals.end();
}

/// The back end's converged frame of `setup`: settled (completed at once where it can), then
/// rendered as it is shown.
inline FrameStats render_settled(RenderSession& session, const FrameSetup& setup, FrameBuffers& out) {
  session.settle(setup, RenderSession::kMaxSettleFrames, RenderSession::Settle::complete);
  return session.render(setup, out);
}

inline FrameStats render_settled(RenderSession& session, FrameBuffers& out, const FrameOutputs& outputs = {}) {
  return render_settled(session, session.setup(0, outputs), out);
}

}  // namespace brickyard::testing
