// The sweep's --csv file: one row per point, every measured figure.
#pragma once

#include <map>
#include <string>
#include <vector>

#include "app/trade_sweep_point.hpp"

namespace tissue::app {

// A number as %.6g, or the empty field when it is not finite (not measured).
std::string csv_num(double v);

// `s` as one quoted CSV field: quotes doubled, so commas and quotes in a
// user's scene name or an error message stay inside it.
std::string csv_quote(const std::string& s);

// The header and one row per point; `truth` (set_path_errors) names each
// max depth's path truth.
std::string csv_text(const std::string& scene, const std::vector<SweepPoint>& points,
                     const std::map<int, std::string>& truth);

}  // namespace tissue::app
