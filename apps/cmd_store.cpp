// Store subcommands: import, info, verify, export.

#include <algorithm>
#include <atomic>
#include <filesystem>
#include <iostream>
#include <mutex>
#include <optional>
#include <set>
#include <tuple>
#include <string>
#include <vector>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "apps/commands.h"
#include "apps/parse.h"
#include "core/atomic_file.h"
#include "core/error.h"
#include "core/parallel.h"
#include "core/progress.h"
#include "core/raw_volume.h"
#include "core/units.h"
#include "fields/field.h"
#include "preprocess/builder.h"
#include "preprocess/octree_builder.h"
#include "preprocess/export.h"
#include "preprocess/volume_source.h"
#include "storage/store.h"
#include "storage/store_lock.h"

namespace brickyard::cli {

std::string incomplete_reason(const std::string& path) {
  const auto pid = store_writer_pid(path);
  if (!pid) return "build interrupted";
  return *pid > 0 ? fmt::format("being built by process {}", *pid) : std::string("being built by another process");
}

namespace {

namespace fs = std::filesystem;

// ----------------------------------------------------------------------------------- import

struct ImportOptions {
  std::vector<std::string> sources;  ///< several: the time steps of one grid, in order
  std::string source;                ///< the one being opened (sources[0] until then)
  std::string out;
  // raw
  std::string dims, type, endian = "little", spacing, origin;
  uint64_t header_bytes = 0;
  // field
  std::string size = "256";
  std::vector<std::string> params;
  // vdb
  std::string grid;
  // NIfTI and netCDF
  std::optional<int64_t> time_step;
  std::string time_step_text;  ///< --time-step as given: N, or all
  // netCDF
  std::string variable;
  // DICOM
  std::string series;
  // build
  int brick_size = 32, apron = 1, hc_level = 9;
  std::string codec = "lz4", downsample = "auto", nonfinite = "reject", range, map_size, transaction_size;
  std::string background, convert;
  double constant_tolerance = 0, checkpoint_seconds = 5;
  bool no_shuffle = false, no_map_growth = false, force = false, octree = false, no_disk_check = false, level_set = false;
  // meshes
  MeshImportOptions mesh;
  std::vector<std::string> given;  ///< the options on the command line, by their long names
};

bool has_extension(const std::string& path, std::initializer_list<const char*> exts) {
  std::string ext = fs::path(path).extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char c) { return char(std::tolower(c)); });
  return std::any_of(exts.begin(), exts.end(), [&](const char* e) { return ext == e; });
}

/// Whether `path` names a DICOM series: a directory (of slice files), or a .dcm file (one slice,
/// or a multi-frame volume).
bool is_dicom_path(const std::string& path) {
  std::error_code ec;
  return fs::is_directory(path, ec) || has_extension(path, {".dcm"});
}

/// Whether `path` names a NIfTI file: .nii or .hdr, gzip-compressed or not (extension() sees
/// only ".gz"), or an .img with its .hdr beside it (a raw file may be called .img too).
bool is_nifti_path(const std::string& path) {
  std::string name = fs::path(path).filename().string();
  std::transform(name.begin(), name.end(), name.begin(), [](unsigned char c) { return char(std::tolower(c)); });
  const bool gz = name.ends_with(".gz");
  if (gz) name.resize(name.size() - 3);
  if (name.ends_with(".nii") || name.ends_with(".hdr")) return true;
  if (!name.ends_with(".img")) return false;
  const std::string stem = path.substr(0, path.size() - (gz ? 3 : 0) - 4);
  std::error_code ec;
  return fs::exists(stem + ".hdr", ec) || fs::exists(stem + ".HDR", ec) || fs::exists(stem + ".hdr.gz", ec);
}

std::unique_ptr<VolumeSource> open_source(const ImportOptions& o) {
  if (o.source.rfind("field:", 0) == 0) {
    FieldParamValues params;
    for (const auto& s : o.params) params.insert(parse_assignment(s, "--set"));
    const ValueType type = value_type_from_string(o.type.empty() ? "f32" : o.type, "--type");
    return make_field_source(make_field(o.source.substr(6), params), parse_size(o.size, "--size"), type);
  }
  if (!o.params.empty()) throw Error(Errc::invalid_argument, "--set applies to field: sources only").with_field("--set");
  ConvertOptions convert;
  if (!o.convert.empty()) {
    if (o.convert != "f32")
      throw Error(Errc::invalid_argument, fmt::format("'{}' is not a conversion brickyard makes (only f32)", o.convert))
          .with_field("--convert");
    convert.accept_rounding = true;
  }
  if (is_dicom_path(o.source)) return open_dicom_source(o.source, DicomOptions{o.series, convert});
  if (is_nifti_path(o.source)) return open_nifti_source(o.source, NiftiOptions{convert, o.time_step});
  if (has_extension(o.source, {".nc", ".nc4", ".cdf"}))
    return open_netcdf_source(o.source, NetcdfOptions{o.variable, o.time_step, convert});
  if (has_extension(o.source, {".nrrd", ".nhdr"})) return open_nrrd_source(o.source, convert);
  if (has_extension(o.source, {".mhd", ".mha"})) return open_metaimage_source(o.source, convert);
  if (has_extension(o.source, {".vdb"})) return open_vdb_source(o.source, o.grid);
  if (!o.grid.empty()) throw Error(Errc::invalid_argument, "--grid applies to .vdb sources only").with_field("--grid");

  // Raw: the sidecar describes it unless flags say otherwise; flags override the sidecar.
  RawFileSpec spec;
  const std::string sidecar = raw_sidecar_path(o.source);
  std::error_code ec;
  const bool have_sidecar = fs::exists(sidecar, ec);
  if (have_sidecar) {
    const RawVolumeInfo info = read_raw_sidecar(sidecar);
    spec.dims = info.dims;
    spec.type = element_type(info.type);
    spec.little_endian = info.little_endian;
    spec.spacing = info.spacing;
    spec.origin = info.origin;
    spec.range = ValueRange{info.min_value, info.max_value};
    spec.xxh3_64 = info.xxh3_64;
    if (info.source.rfind("field ", 0) == 0) {
      nlohmann::json g = {{"field", info.source.substr(6)}, {"params", nlohmann::json::object()}};
      for (const auto& [name, value] : info.source_params) g["params"][name] = value;
      if (info.quantization) g["quantization"] = {info.quantization->first, info.quantization->second};
      spec.generator_json = g.dump();
    }
  } else if (o.dims.empty() || o.type.empty()) {
    throw Error(Errc::invalid_argument,
                fmt::format("a raw file needs --dims and --type, or a sidecar {} describing it", sidecar))
        .with_file(o.source);
  }
  if (!o.dims.empty()) {
    spec.dims = parse_size(o.dims, "--dims");
    spec.range.reset();  // the sidecar described another layout
    spec.xxh3_64.reset();
    spec.generator_json.clear();
  }
  if (!o.type.empty()) {
    const ElementType t = element_type_from_string(o.type, "--type");
    if (t != spec.type) spec.range.reset(), spec.generator_json.clear();
    spec.type = t;
  }
  if (o.endian != "little" && o.endian != "big")
    throw Error(Errc::invalid_argument, fmt::format("'{}' is neither little nor big", o.endian)).with_field("--endian");
  if (o.endian == "big") spec.little_endian = false;
  spec.header_bytes = o.header_bytes;
  if (!o.spacing.empty()) {
    spec.spacing = parse_vec3(o.spacing, "--spacing");
    if (const std::string problem = spacing_problem(spec.spacing); !problem.empty())
      throw Error(Errc::invalid_argument, problem).with_field("--spacing");
  }
  if (!o.origin.empty()) spec.origin = parse_vec3(o.origin, "--origin");
  spec.convert = convert;
  return open_raw_source(o.source, spec);
}

/// An option that does not apply to the source would be ignored: refused instead, naming the
/// source kind it belongs to (`import field:sphere --dims 4` built a 256^3 grid).
void refuse_options_for_other_sources(const ImportOptions& o) {
  const std::string& src = o.source;
  const bool mesh_field = src.rfind("mesh:", 0) == 0, mesh_file = !mesh_field && is_mesh_source(src);
  const bool field = src.rfind("field:", 0) == 0;
  const bool nrrd = !mesh_file && has_extension(src, {".nrrd", ".nhdr"}), vdb = !mesh_file && has_extension(src, {".vdb"});
  const bool metaimage = !mesh_file && has_extension(src, {".mhd", ".mha"});
  const bool nifti = !mesh_field && !mesh_file && !field && is_nifti_path(src);
  const bool netcdf = !mesh_field && !mesh_file && !field && !nifti && has_extension(src, {".nc", ".nc4", ".cdf"});
  const bool dicom = !mesh_field && !mesh_file && !field && is_dicom_path(src);
  const bool raw = !mesh_field && !mesh_file && !field && !nrrd && !metaimage && !nifti && !netcdf && !vdb && !dicom;
  const std::string kind = mesh_field ? "a mesh:FIELD source" : mesh_file ? "a mesh file" : field ? "a field: source"
                           : nrrd     ? "a NRRD file"          : metaimage ? "a MetaImage file"
                           : dicom    ? "a DICOM series"
                           : nifti    ? "a NIfTI file"         : netcdf    ? "a netCDF file"
                           : vdb      ? "an OpenVDB file"      : "a raw file";
  static const std::set<std::string> raw_only = {"--dims", "--endian", "--header-bytes", "--spacing", "--origin"};
  static const std::set<std::string> mesh_field_only = {"--cells", "--jitter", "--replicate", "--steps", "--move"};
  static const std::set<std::string> mesh_file_only = {"--array", "--single-step"};
  static const std::set<std::string> meshes_take = {"--cluster-tets", "--bvh", "--map-size", "--force", "--set"};
  for (const std::string& opt : o.given) {
    bool applies = true;
    if (opt == "--out") continue;
    if (raw_only.count(opt)) applies = raw;
    else if (opt == "--type") applies = raw || field;
    else if (opt == "--convert") applies = raw || nrrd || metaimage || nifti || netcdf || dicom;
    else if (opt == "--series") applies = dicom;
    else if (opt == "--time-step") applies = nifti || netcdf;
    else if (opt == "--variable") applies = netcdf;
    else if (opt == "--size") applies = field;
    else if (opt == "--set") applies = field || mesh_field;
    else if (opt == "--grid") applies = vdb;
    else if (mesh_field_only.count(opt)) applies = mesh_field;
    else if (mesh_file_only.count(opt)) applies = mesh_file;
    else if (meshes_take.count(opt)) applies = opt == "--cluster-tets" || opt == "--bvh" ? (mesh_field || mesh_file) : true;
    else if (mesh_field || mesh_file) applies = false;  // the grid build's options
    if (!applies)
      throw Error(Errc::invalid_argument, fmt::format("does not apply to {} ({}), and would be ignored", kind, src))
          .with_field(opt);
  }
  if (mesh_field && o.mesh.move != 0 && o.mesh.steps < 2)
    throw Error(Errc::invalid_argument, "moves the vertices from one time step to the next: give --steps 2 or more")
        .with_field("--move");
}

/// --time-step: N (0-based), or all.
void parse_time_step(ImportOptions& o) {
  if (o.time_step_text.empty() || o.time_step_text == "all") return;
  const double v = parse_number(o.time_step_text, "--time-step");
  if (!(v >= 0) || v != std::floor(v) || v > 1e15)
    throw Error(Errc::invalid_argument, fmt::format("'{}' is not a time step (0, 1, ... or all)", o.time_step_text))
        .with_field("--time-step");
  o.time_step = int64_t(v);
}

/// The grid's time steps: one source, several files in order, or every volume of a 4D NIfTI
/// file or netCDF variable (--time-step all).
std::vector<std::unique_ptr<VolumeSource>> open_sources(const ImportOptions& o) {
  std::vector<std::unique_ptr<VolumeSource>> sources;
  if (o.sources.size() > 1) {
    if (o.time_step_text == "all")
      throw Error(Errc::invalid_argument, "takes the time steps of one 4D file; several files are the time steps already")
          .with_field("--time-step");
    for (const std::string& path : o.sources) {
      ImportOptions step = o;
      step.source = path;
      if (is_mesh_source(path) || path.rfind("field:", 0) == 0)
        throw Error(Errc::invalid_argument, "several sources are the time steps of one grid: volume files only, not "
                                            "fields or meshes")
            .with_file(path);
      sources.push_back(open_source(step));
    }
    return sources;
  }
  if (o.time_step_text != "all") {
    sources.push_back(open_source(o));
    return sources;
  }
  ImportOptions step = o;
  step.time_step = 0;
  sources.push_back(open_source(step));
  const auto described = nlohmann::json::parse(sources.front()->describe_json());
  const int64_t steps = described.value("time_steps", int64_t(1));
  for (step.time_step = 1; *step.time_step < steps; ++*step.time_step) sources.push_back(open_source(step));
  return sources;
}

void run_import(ImportOptions o) {
  parse_time_step(o);
  if (o.sources.size() > 1 && is_mesh_source(o.sources.front()))
    throw Error(Errc::invalid_argument, "a mesh's time steps come from its own file (a .pvd, or arrays NAME_0, NAME_1 ...); "
                                        "import one mesh at a time")
        .with_file(o.sources[1]);
  for (const std::string& path : o.sources) {
    o.source = path;
    refuse_options_for_other_sources(o);
  }
  o.source = o.sources.front();
  if (is_mesh_source(o.source)) {
    MeshImportOptions m = o.mesh;
    m.source = o.source;
    m.out = o.out;
    m.params = o.params;
    m.map_size = o.map_size;
    m.force = o.force;
    return run_mesh_import(m);
  }
  const std::vector<std::unique_ptr<VolumeSource>> sources = open_sources(o);
  VolumeSource* const source = sources.front().get();
  // A DICOM directory may hold several series: say which one is imported, and the others.
  if (is_dicom_path(o.source)) std::cout << nlohmann::json::parse(source->describe_json()).value("summary", "") << "\n";
  BuildOptions b;
  b.brick_size = o.brick_size;
  b.apron = o.apron;
  if (o.codec == "lz4") b.codec = Codec::lz4;
  else if (o.codec == "lz4hc") b.codec = Codec::lz4hc;
  else throw Error(Errc::invalid_argument, fmt::format("unknown codec '{}' (expected lz4 or lz4hc)", o.codec)).with_field("--codec");
  b.hc_level = o.hc_level;
  b.shuffle = !o.no_shuffle;
  b.level_set = o.level_set;
  if (o.downsample != "auto") {
    b.downsample = parse_downsample(o.downsample);
    if (o.level_set && b.downsample != Downsample::min)
      throw Error(Errc::invalid_argument, fmt::format("--level-set keeps the zero crossing with the minimum of each "
                                                      "2x2x2 block; --downsample {} would lose thin parts",
                                                      o.downsample))
          .with_field("--downsample");
  }
  if ((o.level_set || source->is_level_set()) && !b.downsample)
    std::cout << "level set: coarser levels keep the zero crossing (--downsample min)\n";
  b.nonfinite = parse_nonfinite(o.nonfinite);
  b.constant_tolerance = o.constant_tolerance;
  if (!(o.checkpoint_seconds >= 0))
    throw Error(Errc::invalid_argument, "the time between checkpoints must be at least 0").with_field("--checkpoint-every");
  b.checkpoint_seconds = o.checkpoint_seconds;
  if (o.background == "auto") b.background_auto = true;
  else if (!o.background.empty()) b.background = parse_number(o.background, "--background");
  if (!o.range.empty()) b.clamp = parse_range(o.range, "--range");
  if (!o.map_size.empty()) b.map_size = parse_bytes(o.map_size, "--map-size");
  if (!o.transaction_size.empty()) b.batch_bytes = parse_bytes(o.transaction_size, "--transaction-size");
  b.map_growth = !o.no_map_growth;
  b.force = o.force;
  b.check_disk = !o.no_disk_check;
  if (o.octree) b.octree = OctreeBuildOptions{};

  const Vec3s d = source->dims();
  std::vector<VolumeSource*> steps;
  uint64_t input_bytes = 0;
  for (const auto& s : sources) steps.push_back(s.get()), input_bytes += s->input_bytes();
  if (steps.size() == 1)
    std::cout << fmt::format("import {} ({}x{}x{} {}) -> {}\n", source->name(), d.x, d.y, d.z, to_string(source->type()), o.out);
  else if (steps.back()->name() == source->name())  // a 4D file's volumes
    std::cout << fmt::format("import {} time steps of {} ({}x{}x{} {} each) -> {}\n", steps.size(), source->name(), d.x, d.y,
                             d.z, to_string(source->type()), o.out);
  else
    std::cout << fmt::format("import {} time steps, {} to {} ({}x{}x{} {} each) -> {}\n", steps.size(), source->name(),
                             steps.back()->name(), d.x, d.y, d.z, to_string(source->type()), o.out);
  Progress progress(fmt::format("import {}{}", fs::path(source->name()).filename().string(),
                                steps.size() > 1 ? fmt::format(" +{} steps", steps.size() - 1) : ""),
                    input_bytes, "B");
  const BuildResult r = build_series(steps, o.out, b, &progress);
  if (!r.up_to_date) progress.finish();  // otherwise it ends without a closing line: no work done
  if (r.up_to_date) {
    const bool octree_missing = o.octree && !r.manifest.octree;
    std::cout << fmt::format("{} is complete and up to date; {}\n", o.out,
                             octree_missing ? "building its octree" : "nothing to do (--force rebuilds)");
    if (octree_missing) run_build_octree(o.out, {});
    return;
  }
  if (r.rebuilt_incomplete) std::cout << "an interrupted earlier build was discarded and rebuilt\n";
  if (r.resumed_at_slice > 0)
    std::cout << fmt::format("resumed an interrupted build of the same import at slice {} of {} ({:.0f}% done before)\n",
                             r.resumed_at_slice, d.z, 100.0 * double(r.resumed_at_slice) / double(d.z));
  if (r.resumed_at_step > 0)
    std::cout << fmt::format("resumed an interrupted build of the same import at time step {} of {} (the steps before it "
                             "were done)\n", r.resumed_at_step, steps.size());
  std::cout << fmt::format("wrote {}: {} levels, {} of bricks from {} of input ({:.2f}x) in {} ({}/s)\n", o.out,
                           r.manifest.levels, format_bytes(double(r.stored_bytes)), format_bytes(double(r.input_bytes)),
                           double(r.input_bytes) / std::max<double>(1, double(r.stored_bytes)), format_duration(r.seconds),
                           format_bytes(double(r.input_bytes) / std::max(1e-9, r.seconds)));
  if (r.conversion) std::cout << fmt::format("{}: {}\n", source->name(), *r.conversion);
  if (o.background == "auto")
    std::cout << fmt::format("background {:g} (the median of the volume's border)\n", r.manifest.background);
  for (const std::string& w : r.warnings) std::cerr << fmt::format("warning: {}: {}\n", source->name(), w);
  if (o.octree) {
    std::cout << fmt::format("wrote the octree of {} in {}\n", o.out, format_duration(r.octree_seconds));
    print_octree_info(r.manifest);
  }
}

// ------------------------------------------------------------------------------------- info

std::string sparkline(const Histogram& h, int width) {
  static const char* bars[] = {" ", "▁", "▂", "▃", "▄", "▅", "▆", "▇", "█"};
  if (h.counts.empty()) return {};
  std::vector<double> cols(size_t(width), 0);
  for (size_t i = 0; i < h.counts.size(); ++i) cols[i * size_t(width) / h.counts.size()] += double(h.counts[i]);
  double mx = *std::max_element(cols.begin(), cols.end());
  std::string out;
  for (double c : cols) {
    // Log scale: volume histograms are dominated by the background bin.
    const double f = mx > 0 && c > 0 ? std::log1p(c) / std::log1p(mx) : 0;
    out += bars[std::clamp(int(std::ceil(f * 8)), 0, 8)];
  }
  return out;
}

void print_info(const std::string& path, const Store& store, bool json);

/// What a store holds; an incomplete one is described as far as it goes, and then the exit
/// status says it cannot be used (a script that checks `info` must not go on to render it).
void run_info(const std::string& path, bool json) {
  Store store(path, {.allow_incomplete = true});
  print_info(path, store, json);
  if (store.manifest().complete) return;
  const bool being_built = store_writer_pid(path).has_value();
  throw Error(Errc::format, fmt::format("the store is incomplete ({}): {}", incomplete_reason(path),
                                        being_built ? "it cannot be used until that build finishes"
                                                    : "run the import again to finish it"))
      .with_file(path);
}

void print_info(const std::string& path, const Store& store, bool json) {
  const Manifest& m = store.manifest();
  if (json) {
    std::cout << m.to_json() << '\n';
    return;
  }
  if (store.kind() == DataKind::tetrahedral) return print_mesh_info(path, store);
  const GridLayout& l = store.layout();
  const BrickFormat& f = m.format;
  std::cout << fmt::format("store {}: {}, format version {}\n", path,
                           m.complete ? "complete" : "INCOMPLETE (" + incomplete_reason(path) + ")", m.format_version);
  std::cout << fmt::format("volume {}x{}x{} {}, spacing ({:g}, {:g}, {:g}), origin ({:g}, {:g}, {:g})\n", m.dims.x, m.dims.y,
                           m.dims.z, to_string(f.type), m.spacing.x, m.spacing.y, m.spacing.z, m.origin.x, m.origin.y,
                           m.origin.z);
  std::cout << fmt::format("bricks {}^3 + apron {}, {}{}, {} levels, node table {}{}\n", f.brick_size, f.apron,
                           to_string(f.codec), f.shuffles() ? " after byte-shuffle" : "", m.levels,
                           format_bytes(double(store.nodes().bytes())), m.time_steps > 1 ? " a time step" : "");
  if (m.time_steps > 1) std::cout << fmt::format("time steps {} (0 to {})\n", m.time_steps, m.time_steps - 1);
  if (!m.complete) return;
  std::cout << fmt::format("values [{:g}, {:g}], background {:g}\n", m.min_value, m.max_value, m.background);
  for (size_t i = 0; i < m.step_ranges.size(); ++i)
    std::cout << fmt::format("  time step {}: values [{:g}, {:g}]\n", i, m.step_ranges[i].min, m.step_ranges[i].max);
  std::cout << (m.time_steps > 1 ? "levels: every time step's bricks together\n\n" : "\n");
  std::cout << fmt::format("{:>5} {:>16} {:>12} {:>9} {:>9} {:>10} {:>10} {:>10} {:>7}\n", "level", "voxels", "bricks",
                           "constant", "empty", "stored", "raw", "on disk", "ratio");
  LevelStats total;
  for (int i = 0; i < l.levels; ++i) {
    const LevelStats& s = m.stats[size_t(i)];
    const Vec3s d = l.level_dims(i);
    std::cout << fmt::format("{:>5} {:>16} {:>12} {:>8.1f}% {:>8.1f}% {:>10} {:>10} {:>10} {:>6.2f}x\n", i,
                             fmt::format("{}x{}x{}", d.x, d.y, d.z), s.bricks, 100.0 * double(s.constant) / double(s.bricks),
                             100.0 * double(s.empty) / double(s.bricks), s.bricks - s.constant,
                             format_bytes(double(s.raw_bytes)), format_bytes(double(s.stored_bytes)),
                             double(s.raw_bytes) / std::max(1.0, double(s.stored_bytes)));
    total.bricks += s.bricks;
    total.constant += s.constant;
    total.empty += s.empty;
    total.raw_bytes += s.raw_bytes;
    total.stored_bytes += s.stored_bytes;
  }
  const double input = double(volume(m.dims)) * double(size_of(f.type)) * double(m.time_steps);
  std::cout << fmt::format("{:>5} {:>16} {:>12} {:>8.1f}% {:>8.1f}% {:>10} {:>10} {:>10} {:>6.2f}x\n", "all", "",
                           total.bricks, 100.0 * double(total.constant) / double(total.bricks),
                           100.0 * double(total.empty) / double(total.bricks), total.bricks - total.constant,
                           format_bytes(double(total.raw_bytes)), format_bytes(double(total.stored_bytes)),
                           double(total.raw_bytes) / std::max(1.0, double(total.stored_bytes)));
  std::cout << fmt::format("input {} -> {} on disk: {:.2f}x smaller, all levels included\n\n", format_bytes(input),
                           format_bytes(double(total.stored_bytes)), input / std::max(1.0, double(total.stored_bytes)));
  const Histogram& h = m.histogram;
  std::cout << fmt::format("histogram [{:g}, {:g}] |{}|\n", h.lo, h.hi, sparkline(h, 64));
  std::cout << fmt::format("quantiles p1 {:g}  p10 {:g}  p50 {:g}  p90 {:g}  p99 {:g}\n\n", h.quantile(0.01),
                           h.quantile(0.1), h.quantile(0.5), h.quantile(0.9), h.quantile(0.99));
  print_octree_info(m);
  std::cout << "source " << nlohmann::json::parse(m.source).dump() << "\n";
  std::cout << "build  " << nlohmann::json::parse(m.build).dump() << "\n";
}

// ----------------------------------------------------------------------------------- verify

/// A mesh store: every cluster page decodes (checksum, sizes), matches its table entry, and its
/// vertices and values lie within the entry's bounds and range.
/// A grid's octree volume: every page the table lists decodes (checksum, header, layout) and its
/// root's range is the table's, and every stored page is in the table.
size_t verify_octree(const std::string& path, const Store& store) {
  if (!store.has_octree()) return 0;
  const OctreeView& view = store.dataset().octree();
  std::vector<std::string> bad;
  std::set<uint64_t> listed;
  for (const OctreePageRange& p : view.pages()) listed.insert(p.id);
  auto txn = store.begin_read();
  store.for_each_page(txn, RecordKind::octree_page, [&](const PageKey& k, std::span<const std::byte>) {
    if (!listed.count(k.id)) bad.push_back(fmt::format("{}: stored but not in the page table", describe_octree_page(k.id)));
    return true;
  });
  std::vector<std::byte> page(view.page_bytes());
  for (const OctreePageRange& p : view.pages()) {
    try {
      store.read_page(txn, {RecordKind::octree_page, p.id}, page);
      dispatch_value_type(view.layout().type, [&](auto tag) {
        const auto v = OctreePage<decltype(tag)>::view(page, view.layout());
        if (v.nodes[0][0].min != p.min || v.nodes[0][0].max != p.max)
          bad.push_back(fmt::format("{}: root range [{}, {}], the table says [{}, {}]", describe_octree_page(p.id),
                                    v.nodes[0][0].min, v.nodes[0][0].max, p.min, p.max));
      });
    } catch (const Error& e) {
      bad.push_back(fmt::format("{}: {}", describe_octree_page(p.id), e.message()));
    }
  }
  for (const std::string& b : bad) std::cout << "BAD " << b << "\n";
  std::cout << fmt::format("{}: octree of {} pages decoded, {} problems\n", path, view.pages().size(), bad.size());
  return bad.size();
}

int run_verify(const std::string& path) {
  Store store(path, {.allow_incomplete = true});
  if (!store.manifest().complete) {
    std::cout << fmt::format("{}: INCOMPLETE ({}); nothing else checked\n", path, incomplete_reason(path));
    return 1;
  }
  if (store.kind() == DataKind::tetrahedral) return verify_mesh(path, store);
  const GridLayout& l = store.layout();
  const BrickFormat& f = store.format();
  const int steps = store.time_steps();
  std::mutex bad_mutex;
  std::vector<std::tuple<int, BrickKey, std::string>> bad;
  int step = 0;  // the time step checked (a grid of several is checked step by step)
  auto report = [&](const BrickKey& k, std::string why) {
    std::lock_guard lock(bad_mutex);
    bad.emplace_back(step, k, std::move(why));
  };

  // Step 1: every stored record belongs to a non-constant node inside the layout.
  {
    auto txn = store.begin_read();
    store.for_each_step_record(txn, [&](int s, const BrickKey& k, std::span<const std::byte>) {
      step = s;
      if (s >= steps) report(k, fmt::format("record of time step {}; the store has {}", s, steps));
      else if (!l.contains(k)) report(k, "record outside the store's layout");
      else if (store.nodes(s).at(k).is_constant()) report(k, "record for a constant node");
      return true;
    });
  }
  // Step 2: every node: flags, and for stored bricks a full decode with checksum and ranges.
  Progress progress("verify", uint64_t(l.total_bricks()) * uint64_t(steps), "bricks");
  std::atomic<int64_t> decoded{0};
  for (step = 0; step < steps; ++step) {
    for (int level = 0; level < l.levels; ++level) {
      const int64_t n = l.brick_count(level);
      parallel_for<int64_t>(0, n, 16, [&](int64_t i0, int64_t i1) {
        auto txn = store.begin_read();
        std::vector<std::byte> buffer(f.bytes());
        for (int64_t i = i0; i < i1; ++i) {
          const BrickKey k = l.key_at(level, i);
          const NodeRecord& node = store.nodes(step).at(k);
          const bool finest = level == l.finest();
          if (bool(node.flags & kNodeFinest) != finest || bool(node.flags & kNodeHasChildren) == finest)
            report(k, fmt::format("node flags 0x{:x} do not match level {}", node.flags, level));
          if (!(node.min <= node.max)) report(k, fmt::format("node range [{}, {}] is inverted", node.min, node.max));
          if (node.is_constant()) {
            if (store.record(txn, k, step)) report(k, "constant node has a record");
            if (node.constant < node.min || node.constant > node.max)
              report(k, fmt::format("constant {} outside the node range [{}, {}]", node.constant, node.min, node.max));
            continue;
          }
          auto rec = store.record(txn, k, step);
          if (!rec) {
            report(k, "record missing");
            continue;
          }
          try {
            decode_brick(f, k, *rec, buffer);
            const BrickHeader h = read_brick_header(*rec, k);
            dispatch_value_type(f.type, [&](auto tag) {
              using T = decltype(tag);
              const T* v = reinterpret_cast<const T*>(buffer.data());
              const auto [mn, mx] = std::minmax_element(v, v + f.voxels());
              if (float(*mn) != h.min || float(*mx) != h.max)
                report(k, fmt::format("header range [{}, {}] but the voxels span [{}, {}]", h.min, h.max, double(*mn), double(*mx)));
              if (node.min < float(*mn) || node.max > float(*mx))
                report(k, fmt::format("node range [{}, {}] is not inside the brick's [{}, {}]", node.min, node.max, double(*mn), double(*mx)));
            });
            decoded.fetch_add(1, std::memory_order_relaxed);
          } catch (const Error& e) {
            report(k, e.message());
          }
        }
        progress.advance(uint64_t(i1 - i0));
      });
    }
  }
  progress.finish();
  std::sort(bad.begin(), bad.end(), [](const auto& a, const auto& b) {
    return std::tie(std::get<0>(a), std::get<1>(a)) < std::tie(std::get<0>(b), std::get<1>(b));
  });
  for (const auto& [s, k, why] : bad)
    std::cout << fmt::format("BAD {}{}: {}\n", steps > 1 ? fmt::format("time step {} ", s) : "", k.to_string(), why);
  std::cout << fmt::format("{}: {} nodes{}, {} bricks decoded, {} problems\n", path, l.total_bricks() * steps,
                           steps > 1 ? fmt::format(" ({} time steps)", steps) : "", decoded.load(), bad.size());
  const size_t octree_problems = verify_octree(path, store);
  return bad.empty() && octree_problems == 0 ? 0 : 1;
}

// ----------------------------------------------------------------------------------- export

void run_export(const std::string& path, std::optional<int> level_given, const std::string& box_text, const std::string& out,
                const std::string& grid, const std::string& encoding, std::optional<int> time_step) {
  Store store(path);
  const int step = time_step.value_or(0);
  if (time_step && store.kind() == DataKind::tetrahedral)
    throw Error(Errc::invalid_argument, "a mesh exports whole, every time step in its .vtu").with_field("--time-step");
  if (step < 0 || step >= store.time_steps())
    throw Error(Errc::invalid_argument, fmt::format("time step {} of a store with {} (0 to {})", step, store.time_steps(),
                                                    store.time_steps() - 1))
        .with_file(path)
        .with_field("--time-step");
  if (store.kind() == DataKind::tetrahedral) {
    if (level_given || !box_text.empty() || !grid.empty())
      throw Error(Errc::invalid_argument, "--level, --box and --grid apply to grids; a mesh exports whole").with_file(path);
    return export_mesh(store, out, encoding.empty() ? "appended" : encoding);
  }
  if (!encoding.empty()) throw Error(Errc::invalid_argument, "--encoding applies to .vtu export of meshes").with_field("--encoding");
  std::optional<VoxelBox> box;
  if (!box_text.empty()) {
    const auto v = parse_int_list(box_text, 6, "--box");
    box = VoxelBox{{v[0], v[1], v[2]}, {v[3], v[4], v[5]}};
  }
  // The name says the format: a raw file written under an image's or another format's name
  // would be read as that format by the next tool.
  const bool to_vdb = has_extension(out, {".vdb"});
  if (!to_vdb && !has_extension(out, {".raw", ".bin", ".dat"}) && !fs::path(out).extension().empty())
    throw Error(Errc::invalid_argument,
                fmt::format("a grid exports to raw bytes (.raw, .bin or .dat, with a .json sidecar beside it) or "
                            "to .vdb; '{}' is neither",
                            fs::path(out).extension().string()))
        .with_field("--out")
        .with_file(out);
  const int level = level_given.value_or(store.layout().finest());
  const VoxelBox region = export_region(store, level, box);
  check_writable(out);  // the VDB writer opens its file only after the whole export
  Progress progress(fmt::format("export level {}", level), uint64_t(volume(region.size())), "voxels");
  if (to_vdb) {
    export_vdb(store, level, region, out, grid, &progress, step);
    progress.finish();
    std::cout << fmt::format("wrote {}\n", out);
    return;
  }
  const RawVolumeInfo info = export_raw(store, level, region, out, &progress, step);
  progress.finish();
  std::cout << fmt::format("wrote {} ({}x{}x{} {}, {}) and {}\n", out, info.dims.x, info.dims.y, info.dims.z,
                           to_string(info.type), format_bytes(double(info.bytes)), raw_sidecar_path(out));
}

}  // namespace

void add_store_commands(CLI::App& app, int& exit_status) {
  {
    auto o = std::make_shared<ImportOptions>();
    auto* cmd = app.add_subcommand("import", "Build a multiresolution brick store from a volume");
    cmd->add_option("SOURCE", o->sources,
                    "A raw file (described by FILE.json or --dims/--type), a .nrrd/.nhdr file, a MetaImage "
                    ".mhd/.mha file, a NIfTI .nii/.nii.gz/.hdr file, a netCDF .nc/.nc4/.cdf file, a DICOM series "
                    "(a directory of slices, or a .dcm file), a .vdb file, "
                    "field:NAME for a procedural field; a mesh (.vtu .pvd .vtk .msh .node/.ele), or mesh:FIELD "
                    "for a procedural tetrahedral mesh. Several volume files: the time steps of one grid, in order "
                    "(every one the same dims, type, spacing and origin)")
        ->required();
    cmd->add_option("-o,--out", o->out, "Store directory")->required();
    auto* raw = "Raw input";
    cmd->add_option("--dims", o->dims, "Raw: NX,NY,NZ (or N)")->group(raw);
    cmd->add_option("-t,--type", o->type,
                    "Raw or field: u8, i8, u16, i16 or f32 (stored as they are); raw also u32, i32 or f64 (stored "
                    "as f32: integers beyond 2^24 need --convert f32, doubles report their rounding)")
        ->group(raw);
    cmd->add_option("--convert", o->convert,
                    "Raw, NRRD, MetaImage, NIfTI, netCDF or DICOM: f32 accepts the rounding of 32-bit integers "
                    "beyond 2^24 (the worst error is reported)")
        ->group(raw);
    cmd->add_option("--endian", o->endian, "Raw: little or big")->capture_default_str()->group(raw);
    cmd->add_option("--header-bytes", o->header_bytes, "Raw: bytes to skip before the data")->group(raw);
    cmd->add_option("--spacing", o->spacing, "Raw: SX,SY,SZ")->group(raw);
    cmd->add_option("--origin", o->origin, "Raw: OX,OY,OZ")->group(raw);
    auto* field = "Field input";
    cmd->add_option("-s,--size", o->size, "Field: grid size N or NX,NY,NZ")->capture_default_str()->group(field);
    cmd->add_option("--set", o->params, "Field: parameter NAME=VALUE (repeatable)")->group(field);
    cmd->add_option("--grid", o->grid, "OpenVDB: grid name (default: the only grid)")->group("OpenVDB input");
    cmd->add_option("--time-step", o->time_step_text,
                    "NIfTI or netCDF: which volume of a 4D file or (time, z, y, x) variable to import (0-based), or "
                    "all: every one, as the time steps of one grid (needed where there are several)")
        ->group("NIfTI input");
    cmd->add_option("--variable", o->variable,
                    "netCDF: the variable to import (default: the only 3D or 4D numeric variable)")
        ->group("netCDF input");
    cmd->add_option("--series", o->series,
                    "DICOM: the SeriesInstanceUID of the series to import (default: the largest in the directory; "
                    "the import names the others)")
        ->group("DICOM input");
    auto* mesh = "Mesh input";
    cmd->add_option("--array", o->mesh.array,
                    "Mesh: the point array to import, or the name of a series NAME_0, NAME_1 ... (time steps); "
                    "default the first")
        ->group(mesh);
    cmd->add_flag("--single-step", o->mesh.single_step, "Mesh: only the first array of a series")->group(mesh);
    cmd->add_option("--cells", o->mesh.cells, "mesh:FIELD: cubes per axis (6 tets each)")->capture_default_str()->group(mesh);
    cmd->add_option("--jitter", o->mesh.jitter, "mesh:FIELD: interior vertices moved by up to this many cells (0 to 0.2)")
        ->capture_default_str()->group(mesh);
    cmd->add_option("--replicate", o->mesh.replicate, "mesh:FIELD: copies per axis side by side (R^3 in all)")
        ->capture_default_str()->group(mesh);
    cmd->add_option("--steps", o->mesh.steps, "mesh:FIELD: time steps (the field moves along x)")->capture_default_str()->group(mesh);
    cmd->add_option("--move", o->mesh.move,
                    "mesh:FIELD with --steps: the vertices move too, a shear of this fraction of the domain per step")
        ->capture_default_str()
        ->group(mesh);
    cmd->add_option("--cluster-tets", o->mesh.cluster_tets, "Mesh: tets a cluster holds at most")->capture_default_str()->group(mesh);
    cmd->add_flag("--bvh", o->mesh.bvh,
                  "Mesh: store each cluster's BVH (tet_bvh's default build) with its page, read instead of built when "
                  "a cluster first arrives")
        ->group(mesh);
    auto* build = "Build";
    cmd->add_option("--brick-size", o->brick_size, "Brick interior edge M: a power of two in [8, 128]")
        ->capture_default_str()->group(build);
    cmd->add_option("--apron", o->apron, "Replicated voxels around each brick: 1 for trilinear, 2 for central differences")
        ->capture_default_str()->group(build);
    cmd->add_option("--codec", o->codec, "lz4 (fast) or lz4hc (smaller, slower to build)")->capture_default_str()->group(build);
    cmd->add_option("--hc-level", o->hc_level, "LZ4-HC level 1..12")->capture_default_str()->group(build);
    cmd->add_flag("--no-shuffle", o->no_shuffle, "Do not byte-shuffle u16/f32 bricks before compression")->group(build);
    cmd->add_option("--downsample", o->downsample,
                    "Coarser levels: average, min or max of each 2x2x2 block; auto: min for level sets (a VDB of class "
                    "level set, or --level-set), else average")
        ->capture_default_str()->group(build);
    cmd->add_flag("--level-set", o->level_set,
                  "The volume is a signed distance, negative inside: coarser levels keep its zero crossing (min), so "
                  "thin parts survive at every level of detail (a VDB level set is one already)")
        ->group(build);
    cmd->add_option("--constant-tolerance", o->constant_tolerance, "Store a brick as constant when max - min <= this")
        ->capture_default_str()->group(build);
    cmd->add_option("--background", o->background,
                    "The value of empty space, or auto (the median of the volume's border: CT air, MRI outside the "
                    "head); constant bricks within --constant-tolerance of it are empty (default: 0, or a VDB's own)")
        ->group(build);
    cmd->add_option("--range", o->range, "Clamp values into LO,HI (stored units) before building")->group(build);
    cmd->add_option("--nonfinite", o->nonfinite, "NaN/Inf voxels: reject, zero, or clamp (to the finite range)")
        ->capture_default_str()->group(build);
    cmd->add_option("--map-size", o->map_size, "Initial LMDB map size, e.g. 64MiB (default: from the input size)")->group(build);
    cmd->add_flag("--no-map-growth", o->no_map_growth, "Fail instead of growing the map when it is full")->group(build);
    cmd->add_option("--transaction-size", o->transaction_size,
                    "Bricks committed per LMDB transaction, e.g. 1MiB (default 32MiB; small ones let crash drills "
                    "land kills mid-commit)")
        ->group(build);
    cmd->add_option("--checkpoint-every", o->checkpoint_seconds,
                    "Seconds between checkpoints a killed import resumes from when run again (at most; a "
                    "checkpoint costing over 5% of the time waits longer); 0: after every row of bricks")
        ->capture_default_str()
        ->group(build);
    cmd->add_flag("--octree", o->octree, "Also build the octree volume (lossless; see build-octree for its options)")
        ->group(build);
    cmd->add_flag("--force", o->force,
                  "Rebuild a complete store made from another source or with other parameters (built beside it and "
                  "swapped in when complete: until then the old store stays)")
        ->group(build);
    cmd->add_flag("--no-disk-check", o->no_disk_check,
                  "Start even when the free disk is below the store's worst case (every brick incompressible); for "
                  "data that compresses well")
        ->group(build);
    cmd->callback([o, cmd] {
      for (const CLI::Option* opt : cmd->get_options())
        if (opt->count() > 0 && !opt->get_positional()) o->given.push_back(opt->get_name());
      naming_options({{"brick_size", "--brick-size"}}, [&] { run_import(*o); });
    });
  }
  {
    auto path = std::make_shared<std::string>();
    auto json = std::make_shared<bool>(false);
    auto* cmd = app.add_subcommand("info", "Describe a store: levels, bricks, compression, histogram, manifest");
    cmd->add_option("STORE", *path, "Store directory")->required();
    cmd->add_flag("--json", *json, "Print the manifest as JSON");
    cmd->callback([path, json] { run_info(*path, *json); });
  }
  {
    auto path = std::make_shared<std::string>();
    auto* cmd = app.add_subcommand("verify", "Decode every brick and check checksums, ranges and node flags");
    cmd->add_option("STORE", *path, "Store directory")->required();
    cmd->callback([path, &exit_status] { exit_status = run_verify(*path); });
  }
  {
    struct ExportOptions {
      std::string store, box, out, grid, encoding;
      std::optional<int> level, time_step;
    };
    auto o = std::make_shared<ExportOptions>();
    auto* cmd = app.add_subcommand("export", "Write one level (or a box of it) as a raw file or an OpenVDB grid; a mesh as .vtu");
    cmd->add_option("STORE", o->store, "Store directory")->required();
    cmd->add_option("-l,--level", o->level, "Level (default: the finest)");
    cmd->add_option("--box", o->box, "X0,Y0,Z0,X1,Y1,Z1: voxels [lo, hi) at that level (default: all)");
    cmd->add_option("-o,--out", o->out, "FILE.raw (with FILE.raw.json), FILE.vdb, or FILE.vtu for a mesh")->required();
    cmd->add_option("--grid", o->grid, "OpenVDB grid name (default: the source grid's name, or density)");
    cmd->add_option("--encoding", o->encoding, "Mesh to .vtu: ascii, binary, appended (raw, default), base64 or zlib");
    cmd->add_option("--time-step", o->time_step, "A grid of several time steps: which one (default 0)");
    cmd->callback([o] { run_export(o->store, o->level, o->box, o->out, o->grid, o->encoding, o->time_step); });
  }
}

}  // namespace brickyard::cli
