// Number and message formatting shared by the trade study's tables and files.
#pragma once

#include <cstddef>
#include <string>

namespace tissue::app {

// `v` through the printf format `f` (one double conversion).
std::string format_number(const char* f, double v);

// A relative error as "1.23 %", or "n/a" when it is not finite (not measured).
std::string percent_text(double rel);

// "L3": uniform level 3 in the tables, notes and plot labels.
std::string level_name(int level);

// Short one-line form of a library error message.
std::string shorten(const std::string& s, std::size_t n = 110);

}  // namespace tissue::app
