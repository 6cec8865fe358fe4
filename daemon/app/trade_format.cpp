#include "app/trade_format.hpp"

#include <cmath>
#include <cstdio>

namespace tissue::app {

std::string format_number(const char* f, double v) {
  char buf[64];
  std::snprintf(buf, sizeof buf, f, v);
  return buf;
}

std::string percent_text(double rel) { return std::isfinite(rel) ? format_number("%.2f %%", 100.0 * rel) : "n/a"; }

// Appended rather than "L" + std::to_string(level): GCC 12 reports a false
// -Wrestrict in that operator+ once it is inlined (a known false positive).
std::string level_name(int level) {
  std::string name = "L";
  name += std::to_string(level);
  return name;
}

std::string shorten(const std::string& s, std::size_t n) { return s.size() <= n ? s : s.substr(0, n) + "..."; }

}  // namespace tissue::app
