#include "render/png_writer.hpp"

#include <png.h>

#include <cstdio>
#include <new>
#include <string>

#include "util/output_file.hpp"

namespace tissue::render {

namespace {

// libpng's largest default width and height (png_set_user_limits).
constexpr int kMaxSide_px = 1000000;

// Where libpng's error callback leaves its message for the setjmp branch
// (libpng otherwise prints to stderr and says nothing useful). libpng writes
// to memory only, so its errors are its own: the system's come from the
// commit, with their errno.
struct PngFailure {
  char message[200] = "libpng failed";
};

void on_png_error(png_structp png, png_const_charp message) {
  auto* failure = static_cast<PngFailure*>(png_get_error_ptr(png));
  std::snprintf(failure->message, sizeof failure->message, "%s", message);
  png_longjmp(png, 1);
}

void on_png_warning(png_structp, png_const_charp) {}  // warnings do not fail a write

// libpng's output, into memory: the picture is encoded whole before the file
// is touched, then written as every output file is (util::PendingOutputFile).
void on_png_write(png_structp png, png_bytep data, png_size_t length) {
  auto* out = static_cast<std::string*>(png_get_io_ptr(png));
  try {
    out->append(reinterpret_cast<const char*>(data), length);
  } catch (const std::bad_alloc&) {
    png_error(png, "out of memory for the encoded picture");  // longjmps: no exception through libpng
  }
}

void on_png_flush(png_structp) {}

}  // namespace

void write_png(const Image& image, const std::string& path) {
  if (image.width < 1 || image.height < 1 || image.width > kMaxSide_px || image.height > kMaxSide_px)
    throw RenderError("cannot write " + path + ": the image is " + std::to_string(image.width) + " x " +
                      std::to_string(image.height) + " pixels (each side must be 1 to " + std::to_string(kMaxSide_px) +
                      ")");
  const std::size_t expected_bytes = 4 * static_cast<std::size_t>(image.width) * image.height;
  if (image.rgba.size() != expected_bytes)
    throw RenderError("cannot write " + path + ": the image has " + std::to_string(image.rgba.size()) +
                      " bytes of pixels, " + std::to_string(image.width) + " x " + std::to_string(image.height) +
                      " RGBA needs " + std::to_string(expected_bytes));
  // Opened first, so a path that cannot be written fails before the work.
  util::PendingOutputFile file;
  if (const std::string why = file.open(path); !why.empty()) throw RenderError("cannot write " + path + ": " + why);
  const auto fail = [&](const std::string& reason) { return RenderError("cannot write " + path + ": " + reason); };
  std::string encoded;
  // Static storage: written by the error callback between setjmp and
  // longjmp, so it must not be a local (whose value would be indeterminate).
  static thread_local PngFailure failure;
  failure = PngFailure{};
  png_structp png = png_create_write_struct(PNG_LIBPNG_VER_STRING, &failure, &on_png_error, &on_png_warning);
  png_infop info = png ? png_create_info_struct(png) : nullptr;
  if (!png || !info) {
    png_destroy_write_struct(&png, &info);
    throw fail("libpng could not start");
  }
  // libpng reports errors by longjmp: nothing with a destructor is created
  // between here and the end of the writing.
  if (setjmp(png_jmpbuf(png))) {
    png_destroy_write_struct(&png, &info);
    throw fail(failure.message);
  }
  png_set_write_fn(png, &encoded, &on_png_write, &on_png_flush);
  png_set_IHDR(png, info, static_cast<png_uint_32>(image.width), static_cast<png_uint_32>(image.height), 8,
               PNG_COLOR_TYPE_RGBA, PNG_INTERLACE_NONE, PNG_COMPRESSION_TYPE_DEFAULT, PNG_FILTER_TYPE_DEFAULT);
  png_write_info(png, info);
  for (int y = 0; y < image.height; ++y)
    png_write_row(png, const_cast<png_bytep>(&image.rgba[4 * static_cast<std::size_t>(y) * image.width]));
  png_write_end(png, nullptr);
  png_destroy_write_struct(&png, &info);
  if (const std::string why = file.commit(encoded); !why.empty()) throw fail(why);
}

Image read_png(const std::string& path) {
  png_image header{};  // libpng's simplified API: no longjmp to manage
  header.version = PNG_IMAGE_VERSION;
  if (!png_image_begin_read_from_file(&header, path.c_str()))
    throw RenderError("cannot read " + path + ": " + header.message);
  header.format = PNG_FORMAT_RGBA;
  Image image;
  image.width = static_cast<int>(header.width);
  image.height = static_cast<int>(header.height);
  image.rgba.resize(PNG_IMAGE_SIZE(header));
  if (!png_image_finish_read(&header, nullptr, image.rgba.data(), 0, nullptr)) {
    const std::string reason = header.message;
    png_image_free(&header);
    throw RenderError("cannot read " + path + ": " + reason);
  }
  return image;
}

}  // namespace tissue::render
