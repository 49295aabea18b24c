#include "core/plot.h"

#include <fcntl.h>
#include <spawn.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cerrno>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <string_view>

#include <fmt/format.h>

#include "core/atomic_file.h"
#include "core/error.h"

extern char** environ;

namespace brickyard {
namespace {

constexpr std::string_view kFailed = "gnuplot failed or is missing (apt-get install gnuplot-nox)";

/// Closes a file descriptor at scope exit unless released.
struct Fd {
  int fd = -1;
  ~Fd() {
    if (fd >= 0) ::close(fd);
  }
};

/// The last few non-empty lines of gnuplot's output (its error is at the end), on one line.
std::string tail_lines(const std::string& output, size_t max_chars = 400) {
  std::string joined;
  size_t end = output.size();
  while (end > 0 && joined.size() < max_chars) {
    const size_t start = output.rfind('\n', end - 1);
    const size_t from = start == std::string::npos ? 0 : start + 1;
    std::string line = output.substr(from, end - from);
    while (!line.empty() && (line.back() == '\r' || line.back() == ' ')) line.pop_back();
    // gnuplot echoes the offending line and a caret under it; the caret line says nothing.
    if (!line.empty() && line.find_first_not_of(" ^") != std::string::npos)
      joined = joined.empty() ? line : line + " | " + joined;
    if (start == std::string::npos) break;
    end = start;
  }
  if (joined.size() > max_chars) joined = "..." + joined.substr(joined.size() - max_chars);
  return joined;
}

/// Runs `gnuplot script`, stdin from /dev/null, stdout and stderr captured. Returns the exit
/// status (127 when gnuplot could not be started) and fills `output`.
int spawn_gnuplot(const std::string& script, std::string& output) {
  int fds[2];
  if (::pipe2(fds, O_CLOEXEC) != 0)
    throw Error(Errc::resource, fmt::format("cannot create a pipe for gnuplot: {}", std::strerror(errno)));
  Fd read_end{fds[0]}, write_end{fds[1]};

  posix_spawn_file_actions_t actions;
  posix_spawn_file_actions_init(&actions);
  posix_spawn_file_actions_addopen(&actions, 0, "/dev/null", O_RDONLY, 0);
  posix_spawn_file_actions_adddup2(&actions, write_end.fd, 1);
  posix_spawn_file_actions_adddup2(&actions, write_end.fd, 2);
  std::string program = "gnuplot";
  std::string argument = script;
  char* argv[] = {program.data(), argument.data(), nullptr};
  pid_t pid = -1;
  const int spawn_error = ::posix_spawnp(&pid, "gnuplot", &actions, nullptr, argv, environ);
  posix_spawn_file_actions_destroy(&actions);
  if (spawn_error != 0) {
    output = spawn_error == ENOENT ? "gnuplot is not on PATH" : std::strerror(spawn_error);
    return 127;
  }
  ::close(write_end.fd);
  write_end.fd = -1;

  // gnuplot reads its script from a file, never from us, so reading to EOF cannot deadlock.
  char buffer[4096];
  for (;;) {
    const ssize_t n = ::read(read_end.fd, buffer, sizeof buffer);
    if (n > 0) {
      if (output.size() < (1u << 20)) output.append(buffer, size_t(n));
    } else if (n == 0 || errno != EINTR) {
      break;
    }
  }
  int status = 0;
  while (::waitpid(pid, &status, 0) < 0)
    if (errno != EINTR) return 127;
  if (WIFEXITED(status)) return WEXITSTATUS(status);
  output += fmt::format("\ngnuplot was killed by signal {}", WIFSIGNALED(status) ? WTERMSIG(status) : 0);
  return 128;
}

}  // namespace

std::string gnuplot_quote(std::string_view text) {
  std::string out = "'";
  for (char c : text) {
    if (c == '\n' || c == '\r' || c == '\0')
      throw Error(Errc::invalid_argument, fmt::format("a gnuplot string cannot hold a line break or NUL: '{}'", text));
    if (c == '\'') out += '\'';
    out += c;
  }
  return out + "'";
}

bool gnuplot_available() {
  const char* path = std::getenv("PATH");
  std::string_view dirs = path ? path : "/usr/local/bin:/usr/bin:/bin";
  while (true) {
    const size_t colon = dirs.find(':');
    const std::string_view dir = dirs.substr(0, colon);  // an empty entry means the current directory
    const std::string program = fmt::format("{}/gnuplot", dir.empty() ? std::string_view(".") : dir);
    if (::access(program.c_str(), X_OK) == 0) return true;
    if (colon == std::string_view::npos) return false;
    dirs.remove_prefix(colon + 1);
  }
}

void run_gnuplot(const std::string& script_body, const std::string& png_path, int width, int height) {
  if (width <= 0 || height <= 0)
    throw Error(Errc::invalid_argument, fmt::format("plot size {}x{} must be positive", width, height)).with_file(png_path);
  refuse_to_replace_non_regular(png_path);
  const std::string partial = png_path + ".partial";
  const std::string header = fmt::format("set terminal pngcairo size {},{} font 'sans,11'\nset output {}\n", width,
                                         height, gnuplot_quote(partial));

  // Step 1: the script, in a private temporary file (never beside the PNG, whose directory
  // may be the thing that fails).
  std::string script = (std::filesystem::temp_directory_path() / "brickyard-plot-XXXXXX.gp").string();
  const int script_fd = ::mkstemps(script.data(), 3);
  if (script_fd < 0)
    throw Error(Errc::io, fmt::format("cannot create a temporary gnuplot script: {}", std::strerror(errno))).with_file(script);
  struct RemoveScript {
    const std::string& path;
    ~RemoveScript() { std::remove(path.c_str()); }
  } remove_script{script};
  {
    Fd fd{script_fd};
    for (const std::string* part : {&header, &script_body}) {
      std::string_view rest = *part;
      while (!rest.empty()) {
        const ssize_t n = ::write(fd.fd, rest.data(), rest.size());
        if (n < 0 && errno == EINTR) continue;
        if (n <= 0)
          throw Error(Errc::io, fmt::format("cannot write a temporary gnuplot script: {}", std::strerror(errno))).with_file(script);
        rest.remove_prefix(size_t(n));
      }
    }
    if (::write(fd.fd, "\nunset output\n", 14) != 14)
      throw Error(Errc::io, fmt::format("cannot write a temporary gnuplot script: {}", std::strerror(errno))).with_file(script);
  }

  // Step 2: run it; any failure removes what gnuplot may have begun.
  std::string output;
  const int rc = spawn_gnuplot(script, output);
  std::error_code ec;
  if (rc != 0 || std::filesystem::file_size(partial, ec) == 0 || ec) {
    std::filesystem::remove(partial, ec);
    const std::string detail = tail_lines(output);
    throw Error(Errc::unsupported,
                detail.empty() ? std::string(kFailed) : fmt::format("{}: {}", kFailed, detail))
        .with_file(png_path);
  }

  // Step 3: into place.
  std::filesystem::rename(partial, png_path, ec);
  if (ec) {
    const std::string reason = ec.message();
    std::filesystem::remove(partial, ec);
    throw Error(Errc::io, fmt::format("cannot move into place: {}", reason)).with_file(png_path);
  }
}

}  // namespace brickyard
