// Scene files: YAML text -> a validated tissue::scene::Scene.
//
// The format is documented key by key in docs/scene-format.md. Every problem
// with a scene is reported as a SceneError whose message names the source (the
// file), the full key path inside it (lists indexed, e.g.
// "loads[1].total_force_N[2]") and the reason:
//
//   config/scenes/x.yaml: material.youngs_modulus_Pa: must be > 0 (got -5)
//
// Nothing else escapes these functions for bad input (no yaml-cpp exceptions,
// no crashes); yaml-cpp itself is an implementation detail and never appears
// in this header.
#pragma once

#include "scene/yaml_util.hpp"

#include <memory>
#include <stdexcept>
#include <string>
#include <vector>

#include "scene/scene.hpp"

namespace tissue::scene {

class SceneError : public yaml_util::DocumentError {
 public:
  SceneError(const std::string& source, const std::string& key_path, const std::string& reason)
      : DocumentError(source, key_path, reason, "<scene>") {}
};

// A scene file that could not be read at all (missing, a directory, not
// readable, too large): the fault of whoever named it (a daemon config's
// `scene`, a control request), not of a key inside it.
class SceneFileUnreadable : public SceneError {
 public:
  using SceneError::SceneError;
};

// The SceneError for a value that did not fit the mesh (thrown while the
// body was built): the scene's file, the key path, the reason, and the
// --set that set it, as every other scene error.
SceneError model_error(const Scene& scene, const SceneModelError& e);

// Reads and parses a scene file. A missing, unreadable or oversized file is a
// SceneFileUnreadable naming the file. Scene::source is set to `path`.
Scene load_scene_file(const std::string& path);

// Parses scene text; `source_name` is used in messages, stored in
// Scene::source, and its file stem is the default Scene::name.
Scene parse_scene(const std::string& yaml_text, const std::string& source_name);

// Command-line overrides, each "key.path=value" with the value parsed as YAML,
// e.g. "integrator.dt_s=0.002", "adaptivity.enabled=false",
// "gravity_m_per_s2=[0,0,-9.81]", "loads[0].total_force_N[2]=-2". They are
// applied in order to the YAML tree before conversion, so the same type and
// validation rules apply; missing maps on the path are created, list indices
// must exist. Errors caused by an override say so in their reason.
Scene parse_scene_with_overrides(const std::string& yaml_text, const std::string& source_name,
                                 const std::vector<std::string>& overrides);
Scene load_scene_file_with_overrides(const std::string& path, const std::vector<std::string>& overrides);

// `overrides` with `added` appended and the earlier ones it makes moot left
// out: those whose key path is the same as its (however spelled: probes[02]
// is probes[2]) or lies inside it. A new value for a whole list must not be
// followed by an older one for an element the new list may not have. Throws
// SceneError (source `source`) when `added` is not an override.
std::vector<std::string> with_override_replacing(const std::vector<std::string>& overrides, const std::string& added,
                                                 const std::string& source);

// Physical validation of a scene however it was built (the loaders call it).
// Throws SceneError with source = s.source and YAML-style key paths.
void validate_scene(const Scene& s);

}  // namespace tissue::scene
