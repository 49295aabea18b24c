#pragma once
/// @file params.h
/// @brief A back end's parameters declared once each: name, default, range, documentation and
/// the field of the back end's own parameter struct it binds to. The table gives the
/// declarations BackendInfo::params lists (integer and on/off fields say so, and BackendParams
/// refuses fractions for them) and fills the struct from a session's resolved values.
///
///   struct MyParams { double step{}; int refine{}; bool shadows{}; };
///   const ParamTable<MyParams>& my_params() {
///     static const ParamTable<MyParams> table{
///         {"step", &MyParams::step, 0.5, 1e-3, 16, "sampling step in voxels"},
///         {"refine", &MyParams::refine, 6, 0, 40, "bisection steps"},
///         {"shadows", &MyParams::shadows, 1, 0, 1, "1: cast shadow rays"}};
///     return table;
///   }
///   info.params = my_params().declarations();
///   MyParams p = my_params().bind(values);
///
/// A parameter struct's fields carry no defaults of their own (value-initialise them, `{}`):
/// the table's are the only ones.

#include <cmath>
#include <initializer_list>
#include <string>
#include <type_traits>
#include <variant>
#include <vector>

#include "renderers/common/renderer.h"

namespace brickyard {

template <typename P>
class ParamTable {
 public:
  using Field = std::variant<double P::*, float P::*, int P::*, uint32_t P::*, bool P::*>;
  struct Param {
    std::string name;
    Field field;
    double default_value = 0;
    double lo = 0, hi = 0;
    std::string doc;
  };

  ParamTable(std::initializer_list<Param> params) : params_(params) {}

  /// @brief The declarations for BackendInfo::params, in the table's order.
  std::vector<BackendParam> declarations() const {
    std::vector<BackendParam> out;
    for (const Param& p : params_) {
      BackendParam d{p.name, p.default_value, p.lo, p.hi, p.doc};
      d.integer = !std::holds_alternative<double P::*>(p.field) && !std::holds_alternative<float P::*>(p.field);
      out.push_back(std::move(d));
    }
    return out;
  }

  /// @brief A struct with every field the table names set from `values` (BackendParams holds
  /// every declared parameter, defaults included).
  P bind(const BackendParams& values) const {
    P out{};
    for (const Param& p : params_) {
      const double v = values[p.name];
      std::visit(
          [&](auto member) {
            using T = std::remove_reference_t<decltype(out.*member)>;
            if constexpr (std::is_same_v<T, bool>) out.*member = v != 0;
            else out.*member = T(v);
          },
          p.field);
    }
    return out;
  }

 private:
  std::vector<Param> params_;
};

}  // namespace brickyard
