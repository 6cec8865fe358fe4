#pragma once

#include <string>

#include "render/render.hpp"

namespace tissue::render {

// Writes `image` as an 8-bit RGBA PNG. Throws RenderError naming the file and
// the reason: an image whose size and pixel count disagree (checked before
// the file is touched), the system's error, or libpng's own message. The
// picture is encoded in memory and written as util::PendingOutputFile
// writes: a write that fails part-way leaves the path as it was (an older
// picture there stays), never a truncated one.
void write_png(const Image& image, const std::string& path);

// Reads any PNG as 8-bit RGBA (row 0 at the top), for checking pictures made
// by this project or by third-party viewers. Throws RenderError naming the
// file and libpng's reason.
Image read_png(const std::string& path);

}  // namespace tissue::render
