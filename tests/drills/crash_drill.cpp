// Crash drill (issue 42): `brickyard import` killed with SIGKILL at points spread over a build
// that spans many transactions, the last ones in its final commit; then the same command again,
// which must leave a store that verifies and equals an uninterrupted build record for record.
// Then the same for `--force` rebuilds over a complete store of another field: after a killed
// rebuild the store must still open and hold the old records or the new ones, never neither.
//
//   crash_drill BRICKYARD WORKDIR [KILLS [SIZE [TYPE]]]
//
// ctest runs a small one; the note's figures come from
// `build/tests/crash_drill build/bin/brickyard /tmp/crash 20 512 f32`.

#include <fcntl.h>
#include <signal.h>
#include <spawn.h>
#include <sys/wait.h>

#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <iostream>
#include <map>
#include <string>
#include <thread>
#include <vector>

#include <fmt/format.h>

#include "storage/store.h"

extern char** environ;
namespace fs = std::filesystem;
using namespace brickyard;
using Clock = std::chrono::steady_clock;

namespace {

struct Run {
  int status = -1;
  std::string output;
};

Run run(const std::string& command) {
  Run r;
  std::FILE* pipe = ::popen((command + " 2>&1").c_str(), "r");
  if (!pipe) return r;
  char buf[4096];
  size_t n;
  while ((n = std::fread(buf, 1, sizeof buf, pipe)) > 0) r.output.append(buf, n);
  const int status = ::pclose(pipe);
  r.status = WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
  return r;
}

/// Starts argv, kills it with SIGKILL after `delay` unless it ended first; true when killed.
bool run_and_kill(const std::vector<std::string>& args, double delay) {
  std::vector<char*> argv;
  for (const auto& a : args) argv.push_back(const_cast<char*>(a.c_str()));
  argv.push_back(nullptr);
  posix_spawn_file_actions_t actions;
  posix_spawn_file_actions_init(&actions);
  posix_spawn_file_actions_addopen(&actions, 1, "/dev/null", O_WRONLY, 0);
  posix_spawn_file_actions_addopen(&actions, 2, "/dev/null", O_WRONLY, 0);
  pid_t pid = 0;
  if (posix_spawn(&pid, argv[0], &actions, nullptr, argv.data(), environ) != 0) return false;
  posix_spawn_file_actions_destroy(&actions);
  const auto deadline = Clock::now() + std::chrono::duration<double>(delay);
  int status = 0;
  while (Clock::now() < deadline) {
    if (::waitpid(pid, &status, WNOHANG) == pid) return false;  // finished first
    std::this_thread::sleep_for(std::chrono::microseconds(500));
  }
  ::kill(pid, SIGKILL);
  ::waitpid(pid, &status, 0);
  return WIFSIGNALED(status);
}

/// Every record of a grid store, key and stored bytes.
std::map<uint64_t, std::vector<std::byte>> records(const std::string& dir) {
  const Store store(dir);
  std::map<uint64_t, std::vector<std::byte>> out;
  auto txn = store.begin_read();
  store.for_each_record(txn, [&](const BrickKey& k, std::span<const std::byte> v) {
    out.emplace(k.code(), std::vector<std::byte>(v.begin(), v.end()));
    return true;
  });
  return out;
}

double seconds_since(Clock::time_point t) { return std::chrono::duration<double>(Clock::now() - t).count(); }

}  // namespace

int main(int argc, char** argv) {
  if (argc < 3) {
    std::cerr << "usage: crash_drill BRICKYARD WORKDIR [KILLS [SIZE [TYPE]]]\n";
    return 2;
  }
  const std::string by = fs::absolute(argv[1]).string(), work = argv[2];
  const int kills = argc > 3 ? std::atoi(argv[3]) : 20;
  const std::string size = argc > 4 ? argv[4] : "512", type = argc > 5 ? argv[5] : "f32";
  fs::remove_all(work);
  fs::create_directories(work);
  // Small transactions: a build of many commits, so that kills land in and between them; a
  // checkpoint after every row of bricks, so that most kills leave one to resume from.
  const auto import_args = [&](const std::string& field, const std::string& out, bool force) {
    std::vector<std::string> a = {by, "-q", "import", field, "--size", size, "--type", type, "--brick-size", "32",
                                  "--transaction-size", "1MiB", "--checkpoint-every", "0", "--out", out};
    if (force) a.push_back("--force");
    return a;
  };
  const auto command = [](const std::vector<std::string>& args) {
    std::string c;
    for (const auto& a : args) c += (c.empty() ? "" : " ") + a;
    return c;
  };
  const std::string ref = work + "/ref", old_ref = work + "/old";
  auto started = Clock::now();
  if (Run r = run(command(import_args("field:fbm", ref, false))); r.status != 0) {
    std::cerr << "the uninterrupted build failed:\n" << r.output;
    return 1;
  }
  const double build_seconds = seconds_since(started);
  if (Run r = run(command(import_args("field:sphere", old_ref, false))); r.status != 0) {
    std::cerr << "the old store's build failed:\n" << r.output;
    return 1;
  }
  const auto expected = records(ref), old_expected = records(old_ref);
  std::cout << fmt::format("uninterrupted build: {} records in {:.2f} s\n", expected.size(), build_seconds);

  // Kill points: spread over the build, then the last percent (the final commit).
  std::vector<double> points;
  const int spread = std::max(1, kills - kills / 4);
  for (int i = 1; i <= spread; ++i) points.push_back(double(i) / double(spread + 1));
  for (int i = 0; i < kills - spread; ++i) points.push_back(0.97 + 0.03 * double(i) / double(std::max(1, kills - spread)));

  int failures = 0;
  const auto check = [&](const std::string& what, bool ok, const std::string& detail) {
    if (!ok) {
      ++failures;
      std::cout << "FAIL " << what << ": " << detail << "\n";
    }
    return ok;
  };
  for (bool force : {false, true}) {
    int killed = 0, resumed = 0, kept_old = 0, took_new = 0, from_checkpoint = 0;
    double rerun_seconds = 0;
    for (double f : points) {
      const std::string store = work + "/store";
      fs::remove_all(store);
      if (force) fs::copy(old_ref, store, fs::copy_options::recursive);
      const auto args = import_args("field:fbm", store, force);
      const bool was_killed = run_and_kill(args, f * build_seconds);
      killed += was_killed;
      const std::string what = fmt::format("{} at {:.1f}% of the build", force ? "--force rebuild" : "build", 100 * f);
      if (force && was_killed) {  // the store is the old one or the new one, whole
        try {
          const auto now = records(store);
          if (now == old_expected) ++kept_old;
          else if (now == expected) ++took_new;
          else check(what, false, "after the kill the store holds neither the old records nor the new ones");
        } catch (const std::exception& e) {
          const std::string message = e.what();
          // An unfinished first build is refused as incomplete; after a rebuild's kill the old
          // store must open.
          check(what, false, "after the kill the store does not open: " + message);
        }
      }
      started = Clock::now();
      const Run r = run(command(args));
      rerun_seconds += seconds_since(started);
      from_checkpoint += r.output.find("resumed an interrupted build") != std::string::npos;
      if (!check(what, r.status == 0, "the rerun failed:\n" + r.output)) continue;
      const Run v = run(by + " -q verify " + store);
      if (!check(what, v.status == 0, "verify after the rerun:\n" + v.output)) continue;
      resumed += check(what, records(store) == expected, "the rerun's records differ from the uninterrupted build's");
    }
    std::cout << fmt::format("{}: {} kill points, {} killed mid-build, {} reruns verified and equal to the uninterrupted "
                             "build{}, {} resumed from a checkpoint; reruns {:.2f} s on average\n",
                             force ? "--force rebuilds" : "builds", points.size(), killed, resumed,
                             force ? fmt::format(" (after the kill: {} kept the old store whole, {} had the new one)", kept_old, took_new)
                                   : "",
                             from_checkpoint, rerun_seconds / double(points.size()));
  }
  std::cout << (failures ? fmt::format("{} failures\n", failures) : std::string("all kills recovered\n"));
  return failures ? 1 : 0;
}
