#pragma once
// Helpers shared by the tests: a temporary directory removed at scope exit, and running the
// brickyard binary with captured output.

#include <sys/wait.h>

#include <array>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>

namespace brickyard::testing {

class TempDir {
 public:
  TempDir() {
    std::string tmpl = (std::filesystem::temp_directory_path() / "brickyard-test-XXXXXX").string();
    if (!::mkdtemp(tmpl.data())) std::abort();
    path_ = tmpl;
  }
  ~TempDir() {
    std::error_code ec;
    std::filesystem::remove_all(path_, ec);
  }
  TempDir(const TempDir&) = delete;
  TempDir& operator=(const TempDir&) = delete;
  const std::filesystem::path& path() const { return path_; }
  std::string file(const std::string& name) const { return (path_ / name).string(); }

 private:
  std::filesystem::path path_;
};

struct CommandResult {
  int exit_code = -1;
  std::string output;  // stdout and stderr interleaved
};

/// Runs `command` through the shell with stderr merged into stdout.
inline CommandResult run_command(const std::string& command) {
  CommandResult r;
  std::FILE* pipe = ::popen((command + " 2>&1").c_str(), "r");
  if (!pipe) return r;
  std::array<char, 4096> buf;
  size_t n;
  while ((n = std::fread(buf.data(), 1, buf.size(), pipe)) > 0) r.output.append(buf.data(), n);
  const int status = ::pclose(pipe);
  r.exit_code = WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
  return r;
}

/// Flips `count` payload bytes of every copy of the first brick record found in an LMDB data
/// file (copy-on-write leaves stale copies of pages behind, so the live one is among them).
/// Returns the header bytes of that record (magic through z) for the caller to decode.
inline std::string corrupt_first_brick(const std::string& data_mdb, size_t payload_offset, size_t count) {
  std::ifstream in(data_mdb, std::ios::binary);
  std::string data{std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
  in.close();
  const size_t first = data.find("BYBK");
  if (first == std::string::npos) return {};
  const std::string header = data.substr(first, 28);  // magic .. z: identifies the brick
  for (size_t at = data.find(header); at != std::string::npos; at = data.find(header, at + 1))
    for (size_t i = 0; i < count && at + 64 + payload_offset + i < data.size(); ++i) data[at + 64 + payload_offset + i] ^= char(0x5a);
  std::ofstream(data_mdb, std::ios::binary | std::ios::trunc) << data;
  return header;
}

inline std::string read_file(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

}  // namespace brickyard::testing
