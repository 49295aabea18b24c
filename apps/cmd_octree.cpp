// build-octree, and what `info` says of an octree volume.

#include <iostream>
#include <memory>

#include <fmt/format.h>

#include "apps/commands.h"
#include "apps/parse.h"
#include "core/error.h"
#include "core/progress.h"
#include "core/units.h"
#include "preprocess/octree_builder.h"
#include "storage/store.h"

namespace brickyard::cli {

void print_octree_info(const Manifest& m) {
  if (!m.octree) return;
  const OctreeSummary& o = *m.octree;
  const double raw = double(std::max<uint64_t>(o.raw_bytes, 1));
  std::cout << fmt::format("octree depth {}: {} pages of {} ({} interior nodes, {} caps, {} subtrees consolidated)\n",
                           o.depth, o.pages, format_bytes(double(o.page_bytes)), o.interior_nodes, o.caps, o.consolidated);
  std::cout << fmt::format("octree {} ({:.1f}% of the raw grid's {}), {} on disk ({:.1f}%); {}{}\n",
                           format_bytes(double(o.bytes)), 100.0 * double(o.bytes) / raw, format_bytes(raw),
                           format_bytes(double(o.stored_bytes)), 100.0 * double(o.stored_bytes) / raw,
                           o.tolerance > 0 ? fmt::format("lossy, tolerance {:g}, largest error {:g}", o.tolerance, o.max_error)
                                           : std::string("lossless"),
                           o.clamped ? fmt::format(", values clamped into [{:g}, {:g}]", o.clamp_lo, o.clamp_hi) : std::string());
}

void run_build_octree(const std::string& dir, const OctreeBuildOptions& options) {
  Manifest before = read_manifest(dir);
  if (!before.complete)
    throw Error(Errc::format, "the store is incomplete: its build was interrupted or failed; run the import again").with_file(dir);
  if (before.kind != DataKind::structured)
    throw Error(Errc::unsupported, "an octree volume is built over a grid; this store is a tetrahedral mesh").with_file(dir);
  Progress progress("build-octree", uint64_t(volume(before.dims)), "voxels");
  const OctreeBuildResult r = build_octree(dir, options, &progress);
  progress.finish();
  Manifest after = read_manifest(dir);
  std::cout << fmt::format("wrote the octree of {} in {}\n", dir, format_duration(r.seconds));
  print_octree_info(after);
}

void add_octree_commands(CLI::App& app) {
  struct Options {
    std::string store, range;
    double tolerance = 0;
  };
  auto o = std::make_shared<Options>();
  auto* cmd = app.add_subcommand("build-octree", "Build the octree volume of a grid store (for octree_cgt), beside its bricks");
  cmd->add_option("STORE", o->store, "Store directory")->required();
  cmd->add_option("--tolerance", o->tolerance,
                  "Consolidate a subtree whose voxels all lie within this of one value (stored units; 0: lossless)")
      ->capture_default_str();
  cmd->add_option("--range", o->range, "Clamp values into LO,HI first (lossless inside the range)");
  cmd->callback([o] {
    OctreeBuildOptions b;
    b.tolerance = o->tolerance;
    if (!o->range.empty()) b.clamp = parse_range(o->range, "--range");
    run_build_octree(o->store, b);
  });
}

}  // namespace brickyard::cli
