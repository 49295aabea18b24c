// The fuzz targets as regression tests of the normal build (BRICKYARD_FUZZ off): runs
// LLVMFuzzerTestOneInput over every file of the directories (or files) given, in name order,
// as libFuzzer would run them with -runs=0. A finding aborts, as it does under libFuzzer; the
// terminate handler names the input first.

#include <algorithm>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <exception>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>
#include <vector>

#include "tests/fuzz/fuzz_util.h"

namespace {
std::string g_current;

[[noreturn]] void on_terminate() {
  std::fprintf(stderr, "fuzz replay: input %s ended the process:\n", g_current.c_str());
  if (auto e = std::current_exception()) {
    try {
      std::rethrow_exception(e);
    } catch (const std::exception& x) {
      std::fprintf(stderr, "  uncaught exception: %s\n", x.what());
    } catch (...) {
      std::fprintf(stderr, "  uncaught exception of an unknown type\n");
    }
  }
  std::abort();
}
}  // namespace

int main(int argc, char** argv) {
  namespace fs = std::filesystem;
  std::set_terminate(on_terminate);
  std::vector<fs::path> inputs;
  for (int i = 1; i < argc; ++i) {
    const fs::path p(argv[i]);
    std::error_code ec;
    if (fs::is_directory(p, ec)) {
      for (const auto& entry : fs::directory_iterator(p))
        if (entry.is_regular_file()) inputs.push_back(entry.path());
    } else if (fs::is_regular_file(p, ec)) {
      inputs.push_back(p);
    }  // an absent directory (no regressions yet) is no input
  }
  std::sort(inputs.begin(), inputs.end());
  for (const fs::path& p : inputs) {
    g_current = p.string();
    std::ifstream in(p, std::ios::binary);
    const std::vector<char> bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    LLVMFuzzerTestOneInput(reinterpret_cast<const uint8_t*>(bytes.data()), bytes.size());
  }
  std::printf("fuzz replay: %zu inputs, no findings\n", inputs.size());
  return inputs.empty() ? 1 : 0;  // a target with no corpus tests nothing
}
