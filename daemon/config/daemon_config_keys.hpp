// The daemon config's top-level keys, header-only: the daemon config reader
// checks them, and the scene reader names one when a scene key is unknown but
// is (or is close to) a daemon setting, without linking the daemon's reader.
#pragma once

#include <array>
#include <string_view>

namespace tissue::config {

inline constexpr std::array<std::string_view, 10> kDaemonTopLevelKeys{
    "scene",   "state_dir", "status_interval_s", "max_scene_tets", "device",
    "haptics", "realtime",  "control",           "publish",        "record"};

}  // namespace tissue::config
