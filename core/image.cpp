#include "core/image.h"

#include "core/atomic_file.h"

#include <png.h>

#include <cerrno>
#include <csetjmp>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <memory>

#include <fmt/format.h>

namespace brickyard {
namespace {

struct FileCloser {
  void operator()(std::FILE* f) const { if (f) std::fclose(f); }
};
using FilePtr = std::unique_ptr<std::FILE, FileCloser>;

// libpng reports errors through longjmp; its message is kept here so the Error we throw after
// the jump can say what libpng said.
struct PngErrorState {
  std::jmp_buf jump;
  char message[256] = {};
};

void on_png_error(png_structp png, png_const_charp msg) {
  auto* state = static_cast<PngErrorState*>(png_get_error_ptr(png));
  std::snprintf(state->message, sizeof(state->message), "%s", msg);
  std::longjmp(state->jump, 1);
}
void on_png_warning(png_structp, png_const_charp) {}

}  // namespace

namespace {
// libpng reports errors by longjmp: this function holds no C++ object that a jump could skip.
bool write_png_rows(std::FILE* file, PngErrorState& state, const ImageRGBA8& image) {
  png_structp png = png_create_write_struct(PNG_LIBPNG_VER_STRING, &state, on_png_error, on_png_warning);
  png_infop info = png ? png_create_info_struct(png) : nullptr;
  if (!png || !info) {
    png_destroy_write_struct(&png, nullptr);
    std::snprintf(state.message, sizeof(state.message), "could not allocate libpng state");
    return false;
  }
  if (setjmp(state.jump)) {
    png_destroy_write_struct(&png, &info);
    return false;
  }
  png_init_io(png, file);
  png_set_IHDR(png, info, png_uint_32(image.width()), png_uint_32(image.height()), 8, PNG_COLOR_TYPE_RGBA,
               PNG_INTERLACE_NONE, PNG_COMPRESSION_TYPE_DEFAULT, PNG_FILTER_TYPE_DEFAULT);
  png_set_compression_level(png, 3);  // images are large and re-written often: favour speed
  png_write_info(png, info);
  for (int y = 0; y < image.height(); ++y) png_write_row(png, reinterpret_cast<png_const_bytep>(image.row(y)));
  png_write_end(png, nullptr);
  png_destroy_write_struct(&png, &info);
  return true;
}
}  // namespace

void write_png(const std::string& path, const ImageRGBA8& image) {
  if (image.width() <= 0 || image.height() <= 0)
    throw Error(Errc::invalid_argument, "cannot write an empty image").with_file(path);
  AtomicFile file(path);
  PngErrorState state;
  if (!write_png_rows(file.stream(), state, image))
    throw Error(Errc::io, fmt::format("libpng: {}", state.message)).with_file(path);
  file.commit();
}

namespace {
// Kept apart from read_png so that no C++ object local to the function that calls setjmp is
// modified between setjmp and a longjmp (their values would be indeterminate after it).
bool read_png_into(std::FILE* file, PngErrorState& state, ImageRGBA8& image) {
  png_structp png = png_create_read_struct(PNG_LIBPNG_VER_STRING, &state, on_png_error, on_png_warning);
  png_infop info = png ? png_create_info_struct(png) : nullptr;
  if (!png || !info) {
    png_destroy_read_struct(&png, nullptr, nullptr);
    std::snprintf(state.message, sizeof(state.message), "could not allocate libpng state");
    return false;
  }
  if (setjmp(state.jump)) {
    png_destroy_read_struct(&png, &info, nullptr);
    return false;
  }
  png_init_io(png, file);
  png_set_sig_bytes(png, 8);
  png_read_info(png, info);
  // Normalise every PNG flavour to 8-bit RGBA.
  png_set_expand(png);
  png_set_strip_16(png);
  png_set_gray_to_rgb(png);
  png_set_add_alpha(png, 0xff, PNG_FILLER_AFTER);
  png_read_update_info(png, info);
  image = ImageRGBA8(static_cast<int>(png_get_image_width(png, info)), static_cast<int>(png_get_image_height(png, info)));
  for (int y = 0; y < image.height(); ++y) png_read_row(png, reinterpret_cast<png_bytep>(image.row(y)), nullptr);
  png_read_end(png, nullptr);
  png_destroy_read_struct(&png, &info, nullptr);
  return true;
}
}  // namespace

ImageRGBA8 read_png(const std::string& path) {
  check_readable_file(path);
  FilePtr file(std::fopen(path.c_str(), "rb"));
  if (!file) throw Error(Errc::io, fmt::format("cannot open: {}", std::strerror(errno))).with_file(path);
  png_byte signature[8];
  if (std::fread(signature, 1, 8, file.get()) != 8 || png_sig_cmp(signature, 0, 8) != 0)
    throw Error(Errc::format, "not a PNG file").with_file(path);
  PngErrorState state;
  ImageRGBA8 image;
  if (!read_png_into(file.get(), state, image))
    throw Error(Errc::format, fmt::format("libpng: {}", state.message)).with_file(path);
  return image;
}

}  // namespace brickyard
