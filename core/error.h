#pragma once
/// @file error.h
/// @brief The one error type of every brickyard layer: what failed, and where (file, key, field).
///
/// Library code throws brickyard::Error and never terminates the process; only main()
/// chooses an exit code (see exit_code()). Messages are written for the user who has to fix
/// the input: they name the file, the brick key or the field, and say what was wrong.

#include <exception>
#include <sstream>
#include <string>
#include <string_view>

namespace brickyard {

/// @brief Broad kind of failure; it selects the process exit code and lets callers react.
enum class Errc {
  invalid_argument,  ///< a parameter, option or size the user gave is not acceptable
  io,                ///< the operating system refused a read, write or open
  format,            ///< a file's content does not follow its format (truncated, wrong magic, wrong dims)
  corrupt,           ///< stored data fails its checksum or invariants
  not_found,         ///< a named thing (file, grid, key) does not exist
  unsupported,       ///< valid input that this build cannot handle (newer format version, codec)
  resource,          ///< out of disk, map space, memory budget
  internal,          ///< a broken invariant: a bug in brickyard
};

std::string_view to_string(Errc code);

class Error : public std::exception {
 public:
  Error(Errc code, std::string message);

  /// @brief Chainable context setters: throw Error(...).with_file(path).with_field("dims").
  Error& with_file(std::string_view path);
  Error& with_key(std::string_view key);
  Error& with_field(std::string_view field);

  Errc code() const { return code_; }
  const std::string& message() const { return message_; }
  const std::string& file() const { return file_; }
  const std::string& key() const { return key_; }
  const std::string& field() const { return field_; }

  /// @brief "FILE: key K: field 'F': MESSAGE", with absent parts left out.
  const char* what() const noexcept override { return full_.c_str(); }

 private:
  void compose();

  Errc code_;
  std::string message_, file_, key_, field_, full_;
};

/// @brief Process exit code for an error kind: 2 for usage errors, 4 when memory or disk ran
/// out or would (kExitOutOfResources), 1 otherwise (0 is success).
int exit_code(Errc code);
/// @brief The exit code of a render or flight that drew around records it could not read
/// (corrupt or missing in the store), unless --allow-damaged.
inline constexpr int kExitDamaged = 3;
/// @brief The exit code of Errc::resource, and of an allocation that failed (std::bad_alloc):
/// the same input may succeed with lower settings or on a larger machine.
inline constexpr int kExitOutOfResources = 4;

namespace detail {
[[noreturn]] void check_failed(const char* file, int line, const std::string& what);
template <typename A, typename B>
[[noreturn]] void check_op_failed(const char* file, int line, const char* expr, const A& a, const B& b) {
  std::ostringstream os;
  os << expr << " with " << a << " vs " << b;
  check_failed(file, line, os.str());
}
}  // namespace detail

}  // namespace brickyard

/// Invariant checks: on failure they throw Errc::internal with the location and, for the
/// comparison forms, both operands. BY_DCHECK* compile out of release builds.
#define BY_CHECK(cond) \
  do { if (!(cond)) ::brickyard::detail::check_failed(__FILE__, __LINE__, "check failed: " #cond); } while (0)
#define BY_CHECK_OP(a, op, b)                                                                      \
  do {                                                                                              \
    const auto& by_a_ = (a);                                                                        \
    const auto& by_b_ = (b);                                                                        \
    if (!(by_a_ op by_b_))                                                                          \
      ::brickyard::detail::check_op_failed(__FILE__, __LINE__, "check failed: " #a " " #op " " #b, by_a_, by_b_); \
  } while (0)
#define BY_CHECK_EQ(a, b) BY_CHECK_OP(a, ==, b)
#define BY_CHECK_LE(a, b) BY_CHECK_OP(a, <=, b)
#define BY_CHECK_LT(a, b) BY_CHECK_OP(a, <, b)
#ifdef NDEBUG
#define BY_DCHECK(cond) do {} while (0)
#define BY_DCHECK_LT(a, b) do {} while (0)
#else
#define BY_DCHECK(cond) BY_CHECK(cond)
#define BY_DCHECK_LT(a, b) BY_CHECK_LT(a, b)
#endif
