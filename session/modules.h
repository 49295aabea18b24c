#pragma once
/// @file modules.h
/// @brief Loading back-end modules (renderers/common/module.h) from shared libraries.
///
/// Modules are loaded once, before any session is built, from the thread that will build
/// sessions; they stay loaded for the life of the process (their code backs the entries they
/// registered).

#include <string>
#include <vector>

#include "renderers/common/renderer.h"

namespace brickyard {

/// @brief Loads the module at `path` and lets it register its back ends in `registry`.
/// @throws Error naming the file: not_found (no such file), format (not a shared library, or
/// one without brickyard_module_init), unsupported (built for another module API version),
/// invalid_argument (a back end name registered already).
void load_module(const std::string& path, BackendRegistry& registry = backends());

/// @brief The modules the environment names: BRICKYARD_MODULES, paths separated by ':'.
std::vector<std::string> modules_from_environment();

}  // namespace brickyard
