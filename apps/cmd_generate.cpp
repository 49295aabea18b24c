#include <charconv>
#include <filesystem>
#include <iostream>
#include <string>
#include <vector>

#include <fmt/format.h>

#include "apps/commands.h"
#include "apps/parse.h"
#include "core/error.h"
#include "core/progress.h"
#include "core/raw_volume.h"
#include "core/resources.h"
#include "core/units.h"
#include "fields/field.h"
#include "fields/grid.h"

namespace brickyard::cli {
namespace {

struct GenerateOptions {
  std::string field;
  std::string size = "128";
  std::string type = "f32";
  std::string out;
  std::vector<std::string> params;
  bool list = false;
};

void print_field_list() {
  for (const auto& info : field_catalog()) {
    std::cout << fmt::format("{:<16} {}\n", info.name, info.description);
    for (const auto& p : info.params) std::cout << fmt::format("    {}={:<10g} {}\n", p.name, p.value, p.doc);
  }
}

void run_generate(const GenerateOptions& o) {
  if (o.list) {
    print_field_list();
    return;
  }
  if (o.field.empty()) throw Error(Errc::invalid_argument, "missing FIELD (see --list)").with_field("FIELD");
  if (o.out.empty()) throw Error(Errc::invalid_argument, "missing output file").with_field("--out");

  const Vec3s dims = parse_size(o.size, "--size");
  const ValueType type = value_type_from_string(o.type, "--type");
  const auto bytes = checked_grid_bytes(dims, type);
  if (!bytes)
    throw Error(Errc::invalid_argument,
                fmt::format("{}x{}x{} {} voxels overflow a 64-bit byte count", dims.x, dims.y, dims.z, to_string(type)))
        .with_field("--size");

  FieldParamValues params;
  for (const auto& s : o.params) {
    auto [name, value] = parse_assignment(s, "--set");
    params[name] = value;
  }
  const auto field = make_field(o.field, params);

  namespace fs = std::filesystem;
  const fs::path out_path(o.out);
  const fs::path dir = out_path.has_parent_path() ? out_path.parent_path() : fs::path(".");
  std::error_code ec;
  if (!fs::is_directory(dir, ec))
    throw Error(Errc::not_found, "the output directory does not exist").with_file(dir.string());
  // Raw file plus its temporary twin never coexist, so one copy's worth of space is needed.
  ResourceNeeds needs;
  needs.task = fmt::format("generate of {}x{}x{} {}", dims.x, dims.y, dims.z, to_string(type));
  needs.disk = {*bytes, "the raw file", "a smaller --size or a narrower --type"};
  needs.disk_path = dir.string();
  check_resources(needs);

  GridSampler sampler(*field, dims, type);
  Progress progress(fmt::format("generate {}", field->name()), uint64_t(volume(dims)), "voxels");
  const RawVolumeInfo info = write_raw_grid(sampler, o.out, &progress);
  progress.finish();
  std::cout << fmt::format("wrote {} ({}x{}x{} {}, {}), values in [{:g}, {:g}]\n", o.out, dims.x, dims.y, dims.z,
                           to_string(type), format_bytes(double(info.bytes)), info.min_value, info.max_value);
  std::cout << fmt::format("wrote {}\n", raw_sidecar_path(o.out));
}

}  // namespace

void add_generate_command(CLI::App& app, const GlobalOptions&) {
  auto opts = std::make_shared<GenerateOptions>();
  auto* cmd = app.add_subcommand("generate", "Sample a procedural field onto a grid and write FILE.raw and FILE.raw.json");
  std::string names;
  for (const auto& n : field_names()) names += (names.empty() ? "" : ", ") + n;
  cmd->add_option("FIELD", opts->field, "Field to sample: " + names);
  cmd->add_option("-s,--size", opts->size, "Grid size: N for N^3, or NX,NY,NZ")->capture_default_str();
  cmd->add_option("-t,--type", opts->type, "Value type: u8, i8, u16, i16 or f32 (integer types quantise the field's range, or hold an integer-valued field's values as they are)")
      ->capture_default_str();
  cmd->add_option("-o,--out", opts->out, "Output raw file; its sidecar is written next to it as FILE.json");
  cmd->add_option("--set", opts->params, "Field parameter NAME=VALUE (repeatable; see --list)");
  cmd->add_flag("--list", opts->list, "List the fields and their parameters");
  cmd->callback([opts] { run_generate(*opts); });
}

}  // namespace brickyard::cli
