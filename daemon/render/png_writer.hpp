#pragma once

#include <string>

#include "render/render.hpp"

namespace tissue::render {

// Writes `image` as an 8-bit RGBA PNG. Throws RenderError naming the file.
void write_png(const Image& image, const std::string& path);

}  // namespace tissue::render
