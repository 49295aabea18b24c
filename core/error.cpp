#include "core/error.h"

#include <fmt/format.h>

namespace brickyard {

std::string_view to_string(Errc code) {
  switch (code) {
    case Errc::invalid_argument: return "invalid argument";
    case Errc::io: return "i/o error";
    case Errc::format: return "format error";
    case Errc::corrupt: return "corrupt data";
    case Errc::not_found: return "not found";
    case Errc::unsupported: return "unsupported";
    case Errc::resource: return "out of resources";
    case Errc::internal: return "internal error";
  }
  return "error";
}

Error::Error(Errc code, std::string message) : code_(code), message_(std::move(message)) { compose(); }

Error& Error::with_file(std::string_view path) { file_ = path; compose(); return *this; }
Error& Error::with_key(std::string_view key) { key_ = key; compose(); return *this; }
Error& Error::with_field(std::string_view field) { field_ = field; compose(); return *this; }

void Error::compose() {
  full_ = fmt::format("{}{}{}{}", file_.empty() ? "" : file_ + ": ", key_.empty() ? "" : "key " + key_ + ": ",
                      field_.empty() ? "" : "field '" + field_ + "': ", message_);
}

int exit_code(Errc code) {
  if (code == Errc::invalid_argument) return 2;
  return code == Errc::resource ? kExitOutOfResources : 1;
}

namespace detail {
void check_failed(const char* file, int line, const std::string& what) {
  throw Error(Errc::internal, fmt::format("{} ({}:{})", what, file, line));
}
}  // namespace detail

}  // namespace brickyard
