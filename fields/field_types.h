#pragma once
// Factories of the concrete fields, for the registry in field.cpp only.

#include <memory>

#include "fields/field.h"

namespace brickyard {

std::unique_ptr<Field> make_marschner_lobb(FieldParamReader& params);
std::unique_ptr<Field> make_sphere_sdf(FieldParamReader& params);
std::unique_ptr<Field> make_linear(FieldParamReader& params);
std::unique_ptr<Field> make_torus_sdf(FieldParamReader& params);
std::unique_ptr<Field> make_gyroid(FieldParamReader& params);
std::unique_ptr<Field> make_fbm(FieldParamReader& params);
std::unique_ptr<Field> make_menger(FieldParamReader& params);
std::unique_ptr<Field> make_sparse_blobs(FieldParamReader& params);
std::unique_ptr<Field> make_wavelet(FieldParamReader& params);
std::unique_ptr<Field> make_shepp_logan(FieldParamReader& params);

}  // namespace brickyard
