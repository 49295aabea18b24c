#include "session/modules.h"

#include <dlfcn.h>

#include <cstdlib>
#include <filesystem>

#include <fmt/format.h>

#include "core/error.h"
#include "renderers/common/module.h"

namespace brickyard {

void load_module(const std::string& path, BackendRegistry& registry) {
  std::error_code ec;
  if (!std::filesystem::is_regular_file(path, ec)) throw Error(Errc::not_found, "no such module file").with_file(path);
  // A path without a slash would make dlopen search the library path: always name the file.
  const std::string file = path.find('/') == std::string::npos ? "./" + path : path;
  void* library = ::dlopen(file.c_str(), RTLD_NOW | RTLD_LOCAL);
  if (!library) {
    const char* why = ::dlerror();
    throw Error(Errc::format, fmt::format("cannot load the module: {}", why ? why : "unknown error")).with_file(path);
  }
  using Init = int (*)(int, BackendRegistry*);
  auto init = reinterpret_cast<Init>(::dlsym(library, "brickyard_module_init"));
  if (!init) {
    ::dlclose(library);
    throw Error(Errc::format, "not a brickyard module (no brickyard_module_init; define it with BRICKYARD_MODULE)")
        .with_file(path);
  }
  const int status = init(kModuleApiVersion, &registry);
  if (status != 0)
    throw Error(Errc::unsupported, fmt::format("the module was built for module API version {}, this brickyard has {}; "
                                               "rebuild it against this brickyard",
                                               status, kModuleApiVersion))
        .with_file(path);
}

std::vector<std::string> modules_from_environment() {
  std::vector<std::string> out;
  const char* value = std::getenv("BRICKYARD_MODULES");
  if (!value) return out;
  const std::string list = value;
  for (size_t start = 0; start <= list.size();) {
    const size_t end = std::min(list.find(':', start), list.size());
    if (end > start) out.push_back(list.substr(start, end - start));
    start = end + 1;
  }
  return out;
}

}  // namespace brickyard
