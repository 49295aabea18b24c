#pragma once
/// @file field.h
/// @brief Analytic procedural fields: functions that can be evaluated exactly at any point
/// (the test oracles and the reference renderer's truth) and sampled onto grids of any size
/// (the built-in datasets and benchmark inputs).
///
/// A field is immutable after construction, so one instance may be evaluated from many
/// threads at once. Fields are created by name through make_field(); each declares its
/// parameters with defaults and documentation, and an unknown parameter is an error.

#include <cstdint>
#include <map>
#include <memory>
#include <string>
#include <string_view>
#include <vector>

#include "core/math.h"

namespace brickyard {

/// @brief A closed interval of values.
struct ValueRange {
  double lo = 0.0, hi = 0.0;
  bool contains(double v) const { return v >= lo && v <= hi; }
  friend bool operator==(const ValueRange&, const ValueRange&) = default;
};

/// @brief One declared parameter of a field, with the value in use.
struct FieldParam {
  std::string name;
  double value;
  std::string doc;
};

/// @brief Parameter values given by the user, by name.
using FieldParamValues = std::map<std::string, double, std::less<>>;

class Field {
 public:
  virtual ~Field() = default;

  virtual std::string_view name() const = 0;
  /// @brief The box the field is defined on. Grids sample it vertex-centred: the first and
  /// last samples along each axis lie on the box faces.
  virtual Box3d domain() const = 0;
  /// @brief Bounds of value() over the domain; u8/u16 grids quantise this range.
  virtual ValueRange range() const = 0;
  /// @brief The field at p (field coordinates).
  virtual double value(const Vec3d& p) const = 0;
  /// @brief Gradient at p: analytic where has_analytic_gradient(), else central differences.
  virtual Vec3d gradient(const Vec3d& p) const;
  virtual bool has_analytic_gradient() const { return false; }
  /// @brief Whether value() is an integer everywhere: integer grids whose type holds
  /// range() then store the values themselves rather than quantising the range onto the type.
  virtual bool integer_valued() const { return false; }
  /// @brief out[i] = value(p0 + (i * dx, 0, 0)) for i in [0, n). One virtual call per row,
  /// so the per-sample code is inlined and vectorisable.
  virtual void sample_row(const Vec3d& p0, double dx, int64_t n, double* out) const = 0;

  /// @brief Parameters with the values this instance uses.
  const std::vector<FieldParam>& params() const { return params_; }

 protected:
  std::vector<FieldParam> params_;
};

/// @brief Reads a field's parameters from user values, recording each declared parameter
/// (so params() documents them) and, in finish(), rejecting any the field did not declare.
class FieldParamReader {
 public:
  FieldParamReader(std::string_view field_name, const FieldParamValues& given) : field_(field_name), given_(given) {}
  double get(std::string_view name, double default_value, std::string_view doc);
  /// @brief Like get(), but the value must be an integer in [lo, hi].
  int64_t get_int(std::string_view name, int64_t default_value, int64_t lo, int64_t hi, std::string_view doc);
  /// @brief Throws Error(invalid_argument) for any given parameter that was never read.
  void finish() const;
  const std::vector<FieldParam>& declared() const { return declared_; }

 private:
  std::string field_;
  const FieldParamValues& given_;
  std::vector<FieldParam> declared_;
};

/// @brief CRTP helper: Derived provides `double eval(const Vec3d&) const`; this supplies the
/// virtual value() and a row loop that the compiler inlines and vectorises.
template <typename Derived>
class FieldBase : public Field {
 public:
  double value(const Vec3d& p) const final { return self().eval(p); }
  void sample_row(const Vec3d& p0, double dx, int64_t n, double* out) const final {
    for (int64_t i = 0; i < n; ++i) out[i] = self().eval({p0.x + static_cast<double>(i) * dx, p0.y, p0.z});
  }

 private:
  const Derived& self() const { return static_cast<const Derived&>(*this); }
};

/// @brief A field's name, one-line description and parameters at their defaults.
struct FieldInfo {
  std::string name;
  std::string description;
  std::vector<FieldParam> params;
};

/// @brief Every field, in a stable order.
std::vector<FieldInfo> field_catalog();
std::vector<std::string> field_names();
/// @brief Creates a field by name. Unknown names and parameters are Error(invalid_argument)
/// listing the known ones.
std::unique_ptr<Field> make_field(std::string_view name, const FieldParamValues& params = {});

}  // namespace brickyard
