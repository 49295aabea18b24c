// netCDF volumes (classic, 64-bit offset, 64-bit data and netCDF-4/HDF5 files), through netCDF-C:
// one variable of (z, y, x), or one time step of (time, z, y, x), read slab by slab in z with
// nc_get_vara, so that the variable is never held whole.
//
// CF conventions (https://cfconventions.org): scale_factor and add_offset unpack the values
// (integers stay integers where the result is whole and fits, else f32). _FillValue and
// missing_value (compared with the raw, packed values) mark missing voxels, which become one
// background value B that the source reports as its background, so that `--background` defaults
// to it and bricks wholly missing (land, in ocean data) are stored empty. B is chosen beside the
// data rather than taken from the fill value, which is often 1e20 or 9.97e36 (netCDF's default
// float fill) or NaN: such a value would stretch the store's value range and histogram to it, and
// coarser levels and trilinear reads at a coast would mix it into the data. So:
//   f32 stores:      B = floor(smallest valid value) - 1 (the next float below it where that
//                    does not differ), found by a measuring pass before the build;
//   integer stores:  B = smallest valid value - 1, else largest + 1, else the fill value itself
//                    (unpacked), whichever the type holds first.
// A file whose fill values mark no voxel keeps the default background 0. valid_min, valid_max
// and valid_range are not applied, nor are the netCDF default fill values of variables without
// a _FillValue attribute.
//
// Geometry from coordinate variables (1D variables named as their dimension): origin = first
// value, spacing = (last - first) / (n - 1); non-uniform or descending coordinates are refused.
//
// This is the only file that includes netCDF-C's header (netcdf_unavailable.cpp stands in for it
// in builds without the library). netCDF-C is not thread-safe: a source is used by one thread.

#include <sys/stat.h>

#include <algorithm>
#include <cfloat>
#include <cmath>
#include <cstring>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include <netcdf.h>

#include "core/atomic_file.h"
#include "core/error.h"
#include "preprocess/volume_source.h"

namespace brickyard {
namespace {

/// The element types brickyard reads; nullopt for the rest (64-bit integers, char, string,
/// user-defined types).
std::optional<ElementType> element_of(nc_type type) {
  switch (type) {
    case NC_BYTE: return ElementType::i8;
    case NC_UBYTE: return ElementType::u8;
    case NC_SHORT: return ElementType::i16;
    case NC_USHORT: return ElementType::u16;
    case NC_INT: return ElementType::i32;
    case NC_UINT: return ElementType::u32;
    case NC_FLOAT: return ElementType::f32;
    case NC_DOUBLE: return ElementType::f64;
    default: return std::nullopt;
  }
}

/// CDL's name of a netCDF type.
std::string type_name(nc_type type) {
  switch (type) {
    case NC_BYTE: return "byte";
    case NC_UBYTE: return "ubyte";
    case NC_CHAR: return "char";
    case NC_SHORT: return "short";
    case NC_USHORT: return "ushort";
    case NC_INT: return "int";
    case NC_UINT: return "uint";
    case NC_INT64: return "int64";
    case NC_UINT64: return "uint64";
    case NC_FLOAT: return "float";
    case NC_DOUBLE: return "double";
    case NC_STRING: return "string";
    default: return fmt::format("a user-defined type ({})", type);
  }
}

bool is_numeric(nc_type type) { return type != NC_CHAR && type != NC_STRING && type <= NC_UINT64 && type > 0; }

std::string format_name(int format) {
  switch (format) {
    case NC_FORMAT_CLASSIC: return "classic";
    case NC_FORMAT_64BIT_OFFSET: return "64-bit offset";
    case NC_FORMAT_64BIT_DATA: return "64-bit data";
    case NC_FORMAT_NETCDF4: return "netCDF-4";
    case NC_FORMAT_NETCDF4_CLASSIC: return "netCDF-4 classic model";
    default: return fmt::format("format {}", format);
  }
}


bool is_float(ElementType t) { return t == ElementType::f32 || t == ElementType::f64; }

/// `v` as an element of type `t` holds it (NaN for floats), or nullopt when it cannot: a raw
/// value compared with a missing_value of another type (a double 1e20 for a float variable)
/// matches what the variable holds.
std::optional<double> as_element(double v, ElementType t) {
  if (t == ElementType::f64) return v;
  if (t == ElementType::f32) {
    if (std::isfinite(v) && std::fabs(v) > double(FLT_MAX)) return std::nullopt;
    return double(float(v));
  }
  const auto [lo, hi] = element_limits(t);
  if (!is_whole(v) || v < lo || v > hi) return std::nullopt;
  return v;
}

/// A number for the provenance JSON: NaN and infinities as text (JSON has no such numbers).
nlohmann::json json_number(double v) {
  if (std::isnan(v)) return "NaN";
  if (std::isinf(v)) return v > 0 ? "inf" : "-inf";
  return v;
}

std::string quoted_list(const std::vector<std::string>& names) {
  std::string s;
  for (const auto& n : names) s += (s.empty() ? "'" : ", '") + n + "'";
  return s.empty() ? "none" : s;
}

/// The open file, closed when it goes.
class NcFile {
 public:
  explicit NcFile(const std::string& path) {
    const int status = nc_open(path.c_str(), NC_NOWRITE, &id_);
    if (status != NC_NOERR)
      throw Error(Errc::format, fmt::format("not a netCDF file: {}", nc_strerror(status))).with_file(path);
  }
  ~NcFile() {
    if (id_ >= 0) nc_close(id_);
  }
  NcFile(const NcFile&) = delete;
  NcFile& operator=(const NcFile&) = delete;
  int id() const { return id_; }

 private:
  int id_ = -1;
};

/// What the source needs of the file, read when it is opened.
struct NetcdfHeader {
  std::string path;
  std::string format;
  int varid = -1;
  std::string variable;
  nc_type nctype = NC_NAT;
  ElementType element = ElementType::f32;
  std::vector<std::string> dim_names;
  std::vector<size_t> dim_sizes;
  bool four_d = false;
  int64_t steps = 1;
  int64_t time_step = 0;
  std::optional<double> time_value;
  std::string time_units;
  Vec3s dims{0};
  Vec3d spacing{1.0}, origin{0.0};
  nlohmann::json coordinates = nlohmann::json::object();
  std::string units, long_name, standard_name;
  // CF packing and missing values.
  bool has_scale = false, has_offset = false;
  double scale = 1, offset = 0;
  bool scaled = false;
  std::vector<double> fill_attr, missing_attr;  ///< the attributes' values, as written
  std::vector<double> missing;                  ///< the raw values that mark a missing voxel
  bool nan_missing = false;                     ///< NaN marks a missing voxel
  std::optional<double> fill_value;             ///< the first marker (_FillValue, else missing_value)
};

/// The NC_NOERR of a call, or an error naming the file, the variable and what was asked.
void nc_check(int status, const NetcdfHeader& h, const std::string& what) {
  if (status == NC_NOERR) return;
  throw Error(Errc::format, fmt::format("netCDF-C cannot {}: {}", what, nc_strerror(status)))
      .with_file(h.path)
      .with_field(h.variable);
}

std::string var_name(int nc, int varid) {
  char name[NC_MAX_NAME + 1] = {};
  nc_inq_varname(nc, varid, name);
  return name;
}

std::string dim_name(int nc, int dimid) {
  char name[NC_MAX_NAME + 1] = {};
  nc_inq_dimname(nc, dimid, name);
  return name;
}

/// "temp(time, depth, lat, lon)": a variable with its dimensions, for lists.
std::string var_signature(int nc, int varid) {
  int ndims = 0;
  nc_inq_varndims(nc, varid, &ndims);
  std::vector<int> dimids(size_t(std::max(ndims, 0)));
  nc_inq_vardimid(nc, varid, dimids.data());
  std::string s = var_name(nc, varid) + "(";
  for (size_t i = 0; i < dimids.size(); ++i) s += (i ? ", " : "") + dim_name(nc, dimids[i]);
  return s + ")";
}

/// A text attribute (char or a single string), or "" when absent or of another type.
std::string text_attribute(int nc, int varid, const char* name) {
  nc_type type = NC_NAT;
  size_t len = 0;
  if (nc_inq_att(nc, varid, name, &type, &len) != NC_NOERR) return {};
  if (type == NC_CHAR) {
    std::string s(len, '\0');
    if (nc_get_att_text(nc, varid, name, s.data()) != NC_NOERR) return {};
    while (!s.empty() && s.back() == '\0') s.pop_back();
    return s;
  }
  if (type == NC_STRING && len == 1) {
    char* value = nullptr;
    if (nc_get_att_string(nc, varid, name, &value) != NC_NOERR) return {};
    std::string s = value ? value : "";
    nc_free_string(1, &value);
    return s;
  }
  return {};
}

/// A numeric attribute's values; nullopt when absent. Refuses a text one, naming it VAR:NAME.
std::optional<std::vector<double>> numeric_attribute(int nc, const NetcdfHeader& h, const char* name) {
  nc_type type = NC_NAT;
  size_t len = 0;
  if (nc_inq_att(nc, h.varid, name, &type, &len) != NC_NOERR) return std::nullopt;
  const std::string field = h.variable + ":" + name;
  if (!is_numeric(type) || len == 0)
    throw Error(Errc::format, fmt::format("{} is {}{}: it must be a number", field, type_name(type),
                                          len == 0 ? " with no values" : ""))
        .with_file(h.path)
        .with_field(field);
  std::vector<double> values(len);
  nc_check(nc_get_att_double(nc, h.varid, name, values.data()), h, "read the attribute " + field);
  return values;
}

/// Spacing and origin of one axis from its coordinate variable, if the file has one.
void read_coordinate(int nc, NetcdfHeader& h, int axis, const std::string& dim, int dimid) {
  int cv = -1;
  if (nc_inq_varid(nc, dim.c_str(), &cv) != NC_NOERR) return;
  int ndims = 0, cdim = -1;
  nc_type type = NC_NAT;
  nc_inq_varndims(nc, cv, &ndims);
  nc_inq_vartype(nc, cv, &type);
  if (ndims != 1 || !is_numeric(type)) return;  // not a coordinate variable
  nc_inq_vardimid(nc, cv, &cdim);
  if (cdim != dimid) return;
  const size_t n = size_t(h.dims[axis]);
  std::vector<double> v(n);
  const int status = nc_get_var_double(nc, cv, v.data());
  if (status != NC_NOERR)
    throw Error(Errc::format, fmt::format("netCDF-C cannot read the coordinate variable '{}': {}", dim, nc_strerror(status)))
        .with_file(h.path)
        .with_field(dim);
  for (size_t i = 0; i < n; ++i)
    if (!std::isfinite(v[i]))
      throw Error(Errc::format, fmt::format("coordinate variable '{}' holds {} at index {}", dim, v[i], i))
          .with_file(h.path)
          .with_field(dim);
  const std::string units = text_attribute(nc, cv, "units");
  h.origin[axis] = v.front();
  if (n >= 2) {
    const double step = (v.back() - v.front()) / double(n - 1);
    if (!(step > 0))
      throw Error(Errc::unsupported,
                  fmt::format("coordinate variable '{}' runs from {:g} to {:g}: brickyard's axes increase (a grid "
                              "stored in decreasing {} is not supported)",
                              dim, v.front(), v.back(), dim))
          .with_file(h.path)
          .with_field(dim);
    for (size_t i = 1; i < n; ++i) {
      const double d = v[i] - v[i - 1];
      if (std::fabs(d - step) > 1e-3 * step)
        throw Error(Errc::unsupported,
                    fmt::format("coordinate variable '{}' is not uniform: its step from index {} to {} is {:g}, the "
                                "mean step {:g} (more than 0.1% apart); brickyard's grid is regular",
                                dim, i - 1, i, d, step))
            .with_file(h.path)
            .with_field(dim);
    }
    h.spacing[axis] = step;
  }
  nlohmann::json c = {{"variable", dim}, {"first", v.front()}, {"last", v.back()}};
  if (!units.empty()) c["units"] = units;
  h.coordinates[std::string(1, char('x' + axis))] = c;
}

/// Which variable: the one named, or the only 3D or 4D numeric one.
int choose_variable(int nc, const std::string& path, const std::string& wanted) {
  int nvars = 0;
  nc_inq_nvars(nc, &nvars);
  std::vector<std::string> all, candidates;
  int chosen = -1;
  for (int v = 0; v < nvars; ++v) {
    all.push_back(var_signature(nc, v));
    int ndims = 0;
    nc_type type = NC_NAT;
    nc_inq_varndims(nc, v, &ndims);
    nc_inq_vartype(nc, v, &type);
    if ((ndims == 3 || ndims == 4) && is_numeric(type)) candidates.push_back(var_name(nc, v)), chosen = v;
  }
  if (!wanted.empty()) {
    int varid = -1;
    if (nc_inq_varid(nc, wanted.c_str(), &varid) != NC_NOERR)
      throw Error(Errc::not_found, fmt::format("no variable named '{}'; the file has {}", wanted, quoted_list(all)))
          .with_file(path)
          .with_field("--variable");
    return varid;
  }
  if (candidates.size() == 1) return chosen;
  if (candidates.empty())
    throw Error(Errc::not_found, fmt::format("no 3D or 4D numeric variable to import; the file has {}", quoted_list(all)))
        .with_file(path)
        .with_field("--variable");
  throw Error(Errc::invalid_argument, fmt::format("the file has {} 3D or 4D variables ({}): choose one with --variable",
                                                  candidates.size(), quoted_list(candidates)))
      .with_file(path)
      .with_field("--variable");
}

bool is_time_name(std::string name) {
  std::transform(name.begin(), name.end(), name.begin(), [](unsigned char c) { return char(std::tolower(c)); });
  return name == "time";
}

NetcdfHeader read_header(int nc, const std::string& path, const NetcdfOptions& options) {
  NetcdfHeader h;
  h.path = path;
  int format = 0;
  nc_inq_format(nc, &format);
  h.format = format_name(format);
  h.varid = choose_variable(nc, path, options.variable);
  h.variable = var_name(nc, h.varid);

  // --- Type.
  nc_inq_vartype(nc, h.varid, &h.nctype);
  const auto element = element_of(h.nctype);
  if (!element)
    throw Error(Errc::unsupported, fmt::format("variable '{}' is {}: brickyard reads byte, ubyte, short, ushort and "
                                               "float as they are, and int, uint and double as f32",
                                               h.variable, type_name(h.nctype)))
        .with_file(path)
        .with_field(h.variable);
  h.element = *element;

  // --- Dimensions: (z, y, x), or (time, z, y, x) with the first unlimited or named time.
  int ndims = 0;
  nc_inq_varndims(nc, h.varid, &ndims);
  std::vector<int> dimids(size_t(std::max(ndims, 0)));
  nc_inq_vardimid(nc, h.varid, dimids.data());
  int nunlim = 0;
  std::vector<int> unlimited(size_t(NC_MAX_DIMS));
  if (nc_inq_unlimdims(nc, &nunlim, unlimited.data()) != NC_NOERR) nunlim = 0;
  unlimited.resize(size_t(nunlim));
  std::string signature = var_signature(nc, h.varid);
  for (int id : dimids) {
    size_t len = 0;
    nc_inq_dimlen(nc, id, &len);
    h.dim_names.push_back(dim_name(nc, id));
    h.dim_sizes.push_back(len);
  }
  auto time_like = [&](size_t i) {
    return is_time_name(h.dim_names[i]) ||
           std::find(unlimited.begin(), unlimited.end(), dimids[i]) != unlimited.end();
  };
  if (ndims != 3 && ndims != 4)
    throw Error(Errc::unsupported, fmt::format("variable {} has {} dimension{}: brickyard reads (z, y, x) variables, "
                                               "and (time, z, y, x) ones one time step at a time",
                                               signature, ndims, ndims == 1 ? "" : "s"))
        .with_file(path)
        .with_field(h.variable);
  if (ndims == 3 && time_like(0))
    throw Error(Errc::unsupported, fmt::format("variable {} is a 2D field over time ('{}' is {}), not a volume",
                                               signature, h.dim_names[0],
                                               is_time_name(h.dim_names[0]) ? "named time" : "unlimited"))
        .with_file(path)
        .with_field(h.variable);
  if (ndims == 4 && !time_like(0))
    throw Error(Errc::unsupported, fmt::format("variable {}: the first of its 4 dimensions, '{}', is neither unlimited "
                                               "nor named time; brickyard reads (time, z, y, x)",
                                               signature, h.dim_names[0]))
        .with_file(path)
        .with_field(h.variable);
  h.four_d = ndims == 4;
  const size_t first = h.four_d ? 1 : 0;
  for (int a = 0; a < 3; ++a) {
    const size_t i = first + size_t(2 - a);  // C order: x is the last dimension
    if (h.dim_sizes[i] == 0)
      throw Error(Errc::format, fmt::format("dimension '{}' of variable {} has length 0", h.dim_names[i], signature))
          .with_file(path)
          .with_field(h.variable);
    h.dims[a] = int64_t(h.dim_sizes[i]);
  }
  h.steps = h.four_d ? int64_t(h.dim_sizes[0]) : 1;
  if (options.time_step) {
    if (*options.time_step < 0 || *options.time_step >= h.steps)
      throw Error(Errc::invalid_argument,
                  h.steps == 0 ? fmt::format("time step {} is outside variable '{}', which holds no time steps "
                                             "(dimension '{}' has length 0)",
                                             *options.time_step, h.variable, h.dim_names[0])
                               : fmt::format("time step {} is outside the {} step{} of variable '{}' (0 to {})",
                                             *options.time_step, h.steps, h.steps == 1 ? "" : "s", h.variable,
                                             h.steps - 1))
          .with_file(path)
          .with_field("--time-step");
    h.time_step = *options.time_step;
  } else if (h.steps != 1) {
    // A store holds one volume; time-varying stores are future work.
    throw Error(Errc::invalid_argument,
                h.steps == 0 ? fmt::format("variable '{}' holds no time steps (dimension '{}' has length 0)",
                                           h.variable, h.dim_names[0])
                             : fmt::format("variable '{}' holds {} time steps (dimension '{}'); a store holds one "
                                           "volume: choose it with --time-step 0 to {}",
                                           h.variable, h.steps, h.dim_names[0], h.steps - 1))
        .with_file(path)
        .with_field("--time-step");
  }

  // --- Geometry from the coordinate variables; the time step's value from time's.
  for (int a = 0; a < 3; ++a) {
    const size_t i = first + size_t(2 - a);
    read_coordinate(nc, h, a, h.dim_names[i], dimids[i]);
  }
  if (h.four_d) {
    int tv = -1, tdim = -1, tnd = 0;
    nc_type type = NC_NAT;
    if (nc_inq_varid(nc, h.dim_names[0].c_str(), &tv) == NC_NOERR && nc_inq_varndims(nc, tv, &tnd) == NC_NOERR &&
        tnd == 1 && nc_inq_vartype(nc, tv, &type) == NC_NOERR && is_numeric(type) &&
        nc_inq_vardimid(nc, tv, &tdim) == NC_NOERR && tdim == dimids[0]) {
      const size_t index = size_t(h.time_step);
      double value = 0;
      if (nc_get_var1_double(nc, tv, &index, &value) == NC_NOERR) h.time_value = value;
      h.time_units = text_attribute(nc, tv, "units");
    }
  }
  h.units = text_attribute(nc, h.varid, "units");
  h.long_name = text_attribute(nc, h.varid, "long_name");
  h.standard_name = text_attribute(nc, h.varid, "standard_name");

  // --- CF packing: unpacked = packed * scale_factor + add_offset.
  const std::string field_scale = h.variable + ":scale_factor", field_offset = h.variable + ":add_offset";
  if (const auto s = numeric_attribute(nc, h, "scale_factor")) {
    if (s->size() != 1 || !std::isfinite(s->front()) || s->front() == 0)
      throw Error(Errc::format, fmt::format("{} must be one finite, non-zero number (it has {} value{}, the first {:g})",
                                            field_scale, s->size(), s->size() == 1 ? "" : "s", s->front()))
          .with_file(path)
          .with_field(field_scale);
    h.has_scale = true;
    h.scale = s->front();
  }
  if (const auto o = numeric_attribute(nc, h, "add_offset")) {
    if (o->size() != 1 || !std::isfinite(o->front()))
      throw Error(Errc::format, fmt::format("{} must be one finite number (it has {} value{}, the first {:g})",
                                            field_offset, o->size(), o->size() == 1 ? "" : "s", o->front()))
          .with_file(path)
          .with_field(field_offset);
    h.has_offset = true;
    h.offset = o->front();
  }
  h.scaled = h.scale != 1 || h.offset != 0;

  // --- Missing values, in the raw (packed) type.
  if (const auto f = numeric_attribute(nc, h, "_FillValue")) h.fill_attr = *f;
  if (const auto m = numeric_attribute(nc, h, "missing_value")) h.missing_attr = *m;
  for (const auto* values : {&h.fill_attr, &h.missing_attr})
    for (double v : *values) {
      const auto raw = as_element(v, h.element);
      if (!raw) continue;  // the variable cannot hold it: no voxel is missing by it
      if (!h.fill_value) h.fill_value = *raw;
      if (std::isnan(*raw)) h.nan_missing = true;
      else if (std::find(h.missing.begin(), h.missing.end(), *raw) == h.missing.end()) h.missing.push_back(*raw);
    }
  return h;
}

/// Reads elements of type S into doubles (the raw values).
template <typename S>
void load_raw(const std::byte* in, size_t n, double* out) {
  for (size_t i = 0; i < n; ++i) {
    S v;
    std::memcpy(&v, in + i * sizeof(S), sizeof(S));
    out[i] = double(v);
  }
}

void raw_to_double(const std::byte* in, ElementType t, size_t n, double* out) {
  switch (t) {
    case ElementType::u8: return load_raw<uint8_t>(in, n, out);
    case ElementType::i8: return load_raw<int8_t>(in, n, out);
    case ElementType::u16: return load_raw<uint16_t>(in, n, out);
    case ElementType::i16: return load_raw<int16_t>(in, n, out);
    case ElementType::u32: return load_raw<uint32_t>(in, n, out);
    case ElementType::i32: return load_raw<int32_t>(in, n, out);
    case ElementType::f32: return load_raw<float>(in, n, out);
    case ElementType::f64: return load_raw<double>(in, n, out);
  }
}

class NetcdfSource final : public VolumeSource {
 public:
  NetcdfSource(const std::string& path, const NetcdfOptions& options)
      : file_(path), h_(read_header(file_.id(), path, options)), slice_elements_(size_t(h_.dims.x * h_.dims.y)) {
    struct stat st {};
    if (::stat(path.c_str(), &st) == 0) {
      file_bytes_ = uint64_t(st.st_size);
      mtime_ns_ = int64_t(st.st_mtim.tv_sec) * 1000000000 + st.st_mtim.tv_nsec;
    }
    size_chunk_cache();
    choose_type(options.convert);
  }

  std::string name() const override { return h_.path; }
  Vec3s dims() const override { return h_.dims; }
  ValueType type() const override { return type_; }
  Vec3d spacing() const override { return h_.spacing; }
  Vec3d origin() const override { return h_.origin; }
  double background() const override { return replace_missing_ ? background_ : 0.0; }
  std::optional<ValueRange> value_range_hint() const override { return range_; }
  bool may_contain_nonfinite() const override {
    if (type_ != ValueType::f32) return false;
    if (measured_) return measured_->nonfinite > 0;
    return is_float(h_.element);
  }
  std::optional<ConversionReport> conversion() const override { return conversion_; }
  bool can_skip() const override { return true; }
  void read_slab(int64_t z0, int64_t z1, std::span<std::byte> out) override {
    const size_t n = size_t(z1 - z0) * slice_elements_;
    BY_CHECK_EQ(out.size(), n * size_of(type_));
    const bool plain = !h_.scaled && !replace_missing_;
    if (plain && h_.element == element_type(type_)) {
      read_elements(z0, z1, out);  // stored as it is: straight into the slab
      return;
    }
    raw_.resize(n * size_of(h_.element));
    read_elements(z0, z1, raw_);
    if (plain) {
      convert_elements(raw_.data(), h_.element, n, out.data());
      return;
    }
    values_.resize(n);
    unpack(raw_.data(), n, values_.data(), nullptr);
    // Integer types hold every value exactly (checked when the source was opened).
    store_values(values_.data(), n, type_, out.data());
  }
  std::string describe_json() const override {
    nlohmann::json j = {{"kind", "netcdf"},
                        {"path", h_.path},
                        {"format", h_.format},
                        {"variable", h_.variable},
                        {"type", type_name(h_.nctype)},
                        {"dimensions", h_.dim_names},
                        {"sizes", h_.dim_sizes},
                        {"coordinates", h_.coordinates},
                        {"bytes", file_bytes_},
                        {"mtime_ns", mtime_ns_}};
    if (!h_.units.empty()) j["units"] = h_.units;
    if (!h_.long_name.empty()) j["long_name"] = h_.long_name;
    if (!h_.standard_name.empty()) j["standard_name"] = h_.standard_name;
    if (h_.four_d) {
      j["time_steps"] = h_.steps;
      j["time_step"] = h_.time_step;
      if (h_.time_value) j["time_value"] = json_number(*h_.time_value);
      if (!h_.time_units.empty()) j["time_units"] = h_.time_units;
    }
    if (h_.has_scale) j["scale_factor"] = h_.scale;
    if (h_.has_offset) j["add_offset"] = h_.offset;
    auto numbers = [](const std::vector<double>& v) {
      nlohmann::json a = nlohmann::json::array();
      for (double x : v) a.push_back(json_number(x));
      return a;
    };
    if (!h_.fill_attr.empty()) j["fill_value"] = numbers(h_.fill_attr);
    if (!h_.missing_attr.empty()) j["missing_value"] = numbers(h_.missing_attr);
    if (h_.fill_value) {
      j["missing_voxels"] = missing_voxels_;
      if (replace_missing_) j["missing_as"] = background_;
    }
    if (conversion_) j["conversion"] = nlohmann::json::parse(conversion_->to_json());
    return j.dump();
  }
  uint64_t input_bytes() const override { return uint64_t(volume(h_.dims)) * size_of(h_.element); }

 private:
  /// Slices [z0, z1) of the variable's raw elements (native byte order) into `out`.
  void read_elements(int64_t z0, int64_t z1, std::span<std::byte> out) {
    BY_CHECK_EQ(out.size(), size_t(z1 - z0) * slice_elements_ * size_of(h_.element));
    size_t start[4] = {}, count[4] = {};
    size_t a = 0;
    if (h_.four_d) start[a] = size_t(h_.time_step), count[a] = 1, ++a;
    start[a] = size_t(z0), count[a] = size_t(z1 - z0), ++a;
    start[a] = 0, count[a] = size_t(h_.dims.y), ++a;
    start[a] = 0, count[a] = size_t(h_.dims.x);
    const int status = nc_get_vara(file_.id(), h_.varid, start, count, out.data());
    if (status != NC_NOERR)
      throw Error(Errc::format, fmt::format("netCDF-C cannot read slices {} to {} of variable '{}': {}", z0, z1 - 1,
                                            h_.variable, nc_strerror(status)))
          .with_file(h_.path)
          .with_field(h_.variable);
  }

  bool is_missing(double raw) const {
    if (std::isnan(raw)) return h_.nan_missing;
    for (double m : h_.missing)
      if (raw == m) return true;
    return false;
  }

  /// The values of `n` raw elements, missing ones as the background; `valid`, when given,
  /// receives for each element whether it is not missing.
  void unpack(const std::byte* raw, size_t n, double* out, std::vector<char>* valid) const {
    raw_to_double(raw, h_.element, n, out);
    const bool check = !h_.missing.empty() || h_.nan_missing;
    if (valid) valid->assign(n, 1);
    for (size_t i = 0; i < n; ++i) {
      if (check && is_missing(out[i])) {
        if (valid) (*valid)[i] = 0;
        out[i] = background_;
        continue;
      }
      if (h_.scaled) out[i] = out[i] * h_.scale + h_.offset;
    }
  }

  /// One pass over the variable before the build: the valid values' conversion to f32 (their
  /// range, rounding and non-finite count) and how many voxels are missing.
  ConversionReport measure() {
    const size_t es = size_of(h_.element);
    const size_t slice_bytes = slice_elements_ * es;
    const int64_t slab = std::max<int64_t>(1, std::min<int64_t>(h_.dims.z, int64_t((size_t(32) << 20) / slice_bytes)));
    const ElementType from = h_.scaled ? ElementType::f64 : h_.element;
    ConversionReport report;
    report.from = from;
    std::vector<char> valid;
    std::vector<std::byte> compact;
    for (int64_t z0 = 0; z0 < h_.dims.z; z0 += slab) {
      const int64_t z1 = std::min(h_.dims.z, z0 + slab);
      const size_t n = size_t(z1 - z0) * slice_elements_;
      raw_.resize(n * es);
      read_elements(z0, z1, raw_);
      values_.resize(n);
      unpack(raw_.data(), n, values_.data(), &valid);
      // The valid elements only, as the type the report measures (the raw element, or the
      // unpacked doubles).
      compact.resize(n * size_of(from));
      size_t kept = 0;
      for (size_t i = 0; i < n; ++i) {
        if (!valid[i]) {
          ++missing_voxels_;
          continue;
        }
        if (h_.scaled) std::memcpy(compact.data() + kept * 8, &values_[i], 8);
        else std::memcpy(compact.data() + kept * es, raw_.data() + i * es, es);
        ++kept;
      }
      scan_elements(compact.data(), from, kept, report);
    }
    return report;
  }

  /// The background for missing voxels in stored type `t`, beside the valid values [lo, hi]
  /// (see the top of this file); nullopt when an integer type has no value to spare.
  std::optional<double> missing_background(ValueType t, double lo, double hi) const {
    if (!(lo <= hi)) return 0.0;  // every voxel is missing (or non-finite)
    if (t == ValueType::f32) {
      // Below the smallest value as stored (lo rounded to f32), which large values may round down.
      const float stored_lo = float(lo);
      const float below = float(std::floor(lo) - 1);
      if (std::isfinite(below) && below < stored_lo) return double(below);
      const float next = std::nextafter(stored_lo, -INFINITY);
      if (std::isfinite(next)) return double(next);
      const float above = std::nextafter(float(hi), INFINITY);
      if (std::isfinite(above)) return double(above);
      throw Error(Errc::unsupported, fmt::format("the valid values of '{}' span the whole float range: no value is left "
                                                 "for its {} missing voxels",
                                                 h_.variable, missing_voxels_))
          .with_file(h_.path)
          .with_field(h_.variable);
    }
    if (lo - 1 >= integer_min(t)) return lo - 1;
    if (hi + 1 <= integer_max(t)) return hi + 1;
    const double fill = *h_.fill_value * h_.scale + h_.offset;  // unpacked; it differs from every valid value
    if (is_whole(fill) && range_fits(fill, fill, t)) return fill;
    return std::nullopt;
  }

  /// The stored type: the element's own, or an integer type that holds every unpacked value
  /// exactly (the element's, or i16), else f32. Decided from the element type's range where it
  /// can be; otherwise (and always when missing values are declared) by a measuring pass.
  void choose_type(const ConvertOptions& convert) {
    const bool declares_missing = !h_.missing.empty() || h_.nan_missing;
    std::vector<ValueType> candidates;
    const bool small_integers = h_.element == ElementType::u8 || h_.element == ElementType::i8 ||
                                h_.element == ElementType::u16 || h_.element == ElementType::i16;
    if (!h_.scaled) {
      if (is_native(h_.element) && !is_float(h_.element)) candidates.push_back(stored_type(h_.element));
    } else if (small_integers && is_whole(h_.scale) && is_whole(h_.offset)) {
      candidates.push_back(stored_type(h_.element));
      if (candidates.back() != ValueType::i16) candidates.push_back(ValueType::i16);
    }
    if (!declares_missing) {
      // Without missing values, the element type's range may decide without reading.
      if (!h_.scaled && is_native(h_.element)) {
        type_ = stored_type(h_.element);
        return;
      }
      if (h_.scaled && small_integers && !candidates.empty()) {
        auto [lo, hi] = element_limits(h_.element);
        lo = h_.scale * lo + h_.offset, hi = h_.scale * hi + h_.offset;
        if (lo > hi) std::swap(lo, hi);
        for (ValueType t : candidates)
          if (range_fits(lo, hi, t)) {
            type_ = t;
            return;
          }
      }
    }
    const ConversionReport report = measure();
    measured_ = report;
    replace_missing_ = missing_voxels_ > 0;
    const double lo = report.min, hi = report.max;
    for (ValueType t : candidates) {
      if (lo <= hi && !range_fits(lo, hi, t)) continue;
      if (!replace_missing_) {
        type_ = t;
        if (lo <= hi) range_ = ValueRange{lo, hi};
        return;
      }
      if (const auto b = missing_background(t, lo, hi)) {
        type_ = t;
        background_ = *b;
        range_ = lo <= hi ? ValueRange{std::min(lo, *b), std::max(hi, *b)} : ValueRange{*b, *b};
        return;
      }
    }
    type_ = ValueType::f32;
    if (h_.scaled || !is_native(h_.element)) {
      check_conversion(report, convert, h_.path);
      conversion_ = report;
    }
    if (replace_missing_) background_ = *missing_background(ValueType::f32, lo, hi);
    if (lo <= hi)
      range_ = replace_missing_ ? ValueRange{std::min(lo, background_), std::max(hi, background_)} : ValueRange{lo, hi};
    else if (replace_missing_)
      range_ = ValueRange{background_, background_};
  }

  /// netCDF-4 reads whole chunks through a cache: big enough for every chunk one slice touches,
  /// each chunk is inflated once, not once per slice it spans.
  void size_chunk_cache() {
    int storage = 0;
    std::vector<size_t> chunks(h_.dim_sizes.size());
    if (nc_inq_var_chunking(file_.id(), h_.varid, &storage, chunks.data()) != NC_NOERR || storage != NC_CHUNKED) return;
    const size_t r = chunks.size();
    size_t chunk_bytes = size_of(h_.element), per_slice = 1;
    for (size_t i = 0; i < r; ++i) chunk_bytes *= std::max<size_t>(1, chunks[i]);
    for (size_t i = r - 2; i < r; ++i) per_slice *= (h_.dim_sizes[i] + chunks[i] - 1) / std::max<size_t>(1, chunks[i]);
    size_t size = 0, nelems = 0;
    float preemption = 0;
    if (nc_get_var_chunk_cache(file_.id(), h_.varid, &size, &nelems, &preemption) != NC_NOERR) return;
    const size_t want = std::min<size_t>(per_slice * chunk_bytes + chunk_bytes, size_t(1) << 30);
    if (want > size) nc_set_var_chunk_cache(file_.id(), h_.varid, want, std::max(nelems, 4 * per_slice + 1), preemption);
  }

  NcFile file_;
  NetcdfHeader h_;
  size_t slice_elements_;
  ValueType type_ = ValueType::f32;
  bool replace_missing_ = false;
  double background_ = 0;
  uint64_t missing_voxels_ = 0;
  std::optional<ConversionReport> measured_, conversion_;
  std::optional<ValueRange> range_;
  uint64_t file_bytes_ = 0;
  int64_t mtime_ns_ = 0;
  std::vector<std::byte> raw_;
  std::vector<double> values_;
};

}  // namespace

bool netcdf_support() { return true; }

std::unique_ptr<VolumeSource> open_netcdf_source(const std::string& path, const NetcdfOptions& options) {
  check_readable_file(path);
  return std::make_unique<NetcdfSource>(path, options);
}

}  // namespace brickyard
