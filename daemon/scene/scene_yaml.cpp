#include "scene/scene_yaml.hpp"

#include <yaml-cpp/depthguard.h>
#include <yaml-cpp/eventhandler.h>
#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <array>
#include <cerrno>
#include <charconv>
#include <climits>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <initializer_list>
#include <limits>
#include <map>
#include <optional>
#include <span>
#include <sstream>
#include <string_view>
#include <system_error>
#include <type_traits>
#include <utility>
#include <vector>

namespace tissue::scene {

namespace {

std::string compose_what(const std::string& source, const std::string& key_path, const std::string& reason) {
  std::string out = source.empty() ? std::string("<scene>") : source;
  out += ": ";
  if (!key_path.empty()) {
    out += key_path;
    out += ": ";
  }
  out += reason;
  return out;
}

}  // namespace

SceneError::SceneError(const std::string& source, const std::string& key_path, const std::string& reason)
    : std::runtime_error(compose_what(source, key_path, reason)),
      parts_(std::make_shared<const Parts>(Parts{source, key_path, reason})) {}

namespace {

// Largest scene file we read; anything bigger is not a hand-written scene.
constexpr std::uintmax_t kMaxSceneFileBytes = 16u << 20;
// A guard against typos such as cubes: [4000, 4000, 4] allocating gigabytes.
constexpr long long kMaxTotalCubes = 10'000'000;
constexpr int kMaxDepthLimit = 30;
constexpr std::size_t kMaxNameLength = 64;

// ---------------------------------------------------------------- formatting

std::string fmt_num(double v) {
  if (std::isnan(v)) return "nan";
  if (std::isinf(v)) return v > 0 ? "inf" : "-inf";
  char buf[64];
  const auto r = std::to_chars(buf, buf + sizeof buf, v);
  return std::string(buf, r.ptr);
}

// Text as it may appear in a message: printable ASCII (other bytes as \xNN),
// at most 40 characters.
std::string printable_bare(std::string_view s) {
  std::string out;
  std::size_t n = 0;
  for (const char ch : s) {
    if (n++ == 40) {
      out += "...";
      break;
    }
    const auto c = static_cast<unsigned char>(ch);
    if (c >= 0x20 && c < 0x7f) {
      out += static_cast<char>(c);
    } else {
      char b[8];
      std::snprintf(b, sizeof b, "\\x%02X", static_cast<unsigned>(c));
      out += b;
    }
  }
  return out;
}

std::string printable(std::string_view s) { return "'" + printable_bare(s) + "'"; }

std::string join_list(std::initializer_list<std::string_view> items) {
  std::string out;
  for (const auto& s : items) {
    if (!out.empty()) out += ", ";
    out += s;
  }
  return out;
}

std::string join_key(const std::string& path, std::string_view key) {
  if (path.empty()) return std::string(key);
  std::string out = path;
  out += '.';
  out += key;
  return out;
}

std::string count_of(std::size_t n, const char* noun) { return std::to_string(n) + " " + noun + (n == 1 ? "" : "s"); }

std::string join_index(const std::string& path, std::size_t i) { return path + "[" + std::to_string(i) + "]"; }

// Levenshtein distance, only used to suggest a key for a short typo.
std::size_t edit_distance(std::string_view a, std::string_view b) {
  std::vector<std::size_t> row(b.size() + 1);
  for (std::size_t j = 0; j <= b.size(); ++j) row[j] = j;
  for (std::size_t i = 1; i <= a.size(); ++i) {
    std::size_t diag = row[0];
    row[0] = i;
    for (std::size_t j = 1; j <= b.size(); ++j) {
      const std::size_t up = row[j];
      row[j] = std::min({row[j] + 1, row[j - 1] + 1, diag + (a[i - 1] == b[j - 1] ? 0 : 1)});
      diag = up;
    }
  }
  return row[b.size()];
}

std::optional<std::string_view> suggest(std::string_view key, std::initializer_list<std::string_view> allowed) {
  if (key.empty() || key.size() > 64) return std::nullopt;
  std::optional<std::string_view> best;
  std::size_t best_d = std::max<std::size_t>(2, key.size() / 3) + 1;
  for (const auto& a : allowed) {
    std::size_t d = edit_distance(key, a);
    // "youngs_modulus" for "youngs_modulus_Pa": a missing unit suffix.
    if (a.size() > key.size() && a.substr(0, key.size()) == key && a[key.size()] == '_') d = 1;
    if (d < best_d) {
      best_d = d;
      best = a;
    }
  }
  return best;
}

// ----------------------------------------------------------------- scalars

bool is_digit(char c) { return c >= '0' && c <= '9'; }

// Quoted scalars ("5", '5') and !!str are strings, never numbers or booleans.
bool is_quoted(const YAML::Node& n) { return n.Tag() == "!" || n.Tag() == "tag:yaml.org,2002:str"; }

std::string describe(const YAML::Node& n) {
  switch (n.Type()) {
    case YAML::NodeType::Null:
      return "null";
    case YAML::NodeType::Sequence:
      return "a list";
    case YAML::NodeType::Map:
      return "a map";
    case YAML::NodeType::Scalar:
      return is_quoted(n) ? "the quoted string " + printable(n.Scalar()) : printable(n.Scalar());
    case YAML::NodeType::Undefined:
      break;
  }
  return "nothing";
}

enum class NumberParse { kOk, kNotANumber, kOutOfRange };

// YAML 1.2 core-schema decimal numbers plus the .inf/.nan spellings.
NumberParse parse_float(std::string_view s, double* out) {
  std::string_view t = s;
  bool neg = false;
  if (!t.empty() && (t[0] == '+' || t[0] == '-')) {
    neg = t[0] == '-';
    t.remove_prefix(1);
  }
  if (t == ".inf" || t == ".Inf" || t == ".INF") {
    *out = neg ? -std::numeric_limits<double>::infinity() : std::numeric_limits<double>::infinity();
    return NumberParse::kOk;
  }
  if (s == ".nan" || s == ".NaN" || s == ".NAN") {
    *out = std::numeric_limits<double>::quiet_NaN();
    return NumberParse::kOk;
  }
  std::size_t i = 0, digits = 0;
  while (i < t.size() && is_digit(t[i])) ++i, ++digits;
  if (i < t.size() && t[i] == '.') {
    ++i;
    while (i < t.size() && is_digit(t[i])) ++i, ++digits;
  }
  if (digits == 0) return NumberParse::kNotANumber;
  if (i < t.size() && (t[i] == 'e' || t[i] == 'E')) {
    ++i;
    if (i < t.size() && (t[i] == '+' || t[i] == '-')) ++i;
    std::size_t exp_digits = 0;
    while (i < t.size() && is_digit(t[i])) ++i, ++exp_digits;
    if (exp_digits == 0) return NumberParse::kNotANumber;
  }
  if (i != t.size()) return NumberParse::kNotANumber;
  double v = 0.0;
  const auto [ptr, ec] = std::from_chars(t.data(), t.data() + t.size(), v);
  if (ec == std::errc::result_out_of_range) return NumberParse::kOutOfRange;
  if (ec != std::errc() || ptr != t.data() + t.size()) return NumberParse::kNotANumber;
  *out = neg ? -v : v;
  return NumberParse::kOk;
}

NumberParse parse_int(std::string_view s, int* out) {
  std::string_view t = s;
  if (!t.empty() && t[0] == '+') {
    t.remove_prefix(1);
    if (!t.empty() && t[0] == '-') return NumberParse::kNotANumber;
  }
  const std::size_t first = (!t.empty() && t[0] == '-') ? 1 : 0;
  if (t.size() == first) return NumberParse::kNotANumber;
  for (std::size_t i = first; i < t.size(); ++i)
    if (!is_digit(t[i])) return NumberParse::kNotANumber;
  long long v = 0;
  const auto [ptr, ec] = std::from_chars(t.data(), t.data() + t.size(), v);
  if (ec == std::errc::result_out_of_range || (ec == std::errc() && (v < INT_MIN || v > INT_MAX)))
    return NumberParse::kOutOfRange;
  if (ec != std::errc() || ptr != t.data() + t.size()) return NumberParse::kNotANumber;
  *out = static_cast<int>(v);
  return NumberParse::kOk;
}

// ------------------------------------------------------------ YAML -> Scene

using FieldMap = std::map<std::string, YAML::Node, std::less<>>;

template <class E>
using Choices = std::span<const std::pair<std::string_view, E>>;

constexpr std::array<std::pair<std::string_view, StiffnessLaw>, 2> kStiffnessLaws{
    {{"isotropic", StiffnessLaw::kIsotropic}, {"paper", StiffnessLaw::kPaper}}};
constexpr std::array<std::pair<std::string_view, DampingLaw>, 2> kDampingLaws{
    {{"rayleigh", DampingLaw::kRayleigh}, {"paper", DampingLaw::kPaper}}};
constexpr std::array<std::pair<std::string_view, RefineCriterion>, 2> kCriteria{
    {{"strain_energy", RefineCriterion::kStrainEnergy}, {"stretch", RefineCriterion::kStretch}}};
constexpr std::array<std::pair<std::string_view, IntegratorKind>, 3> kIntegrators{
    {{"explicit", IntegratorKind::kExplicit},
     {"implicit", IntegratorKind::kImplicit},
     {"projective", IntegratorKind::kProjective}}};

template <class E>
std::string choice_names(Choices<E> choices) {
  std::string out;
  for (const auto& c : choices) {
    if (!out.empty()) out += ", ";
    out += c.first;
  }
  return out;
}

class Converter {
 public:
  explicit Converter(const std::string& source) : source_(source) {}

  Scene scene(const YAML::Node& root) {
    if (!root.IsMap()) fail("", "a scene document must be a map of sections, got " + describe(root));
    const FieldMap f = fields(root, "",
                              {"name", "object", "material", "gravity_m_per_s2", "fixed", "prescribed", "loads",
                               "adaptivity", "integrator", "probes"});
    Scene s;
    s.source = source_;
    s.name = default_name(source_);
    opt(f, "name", "", s.name);
    if (s.name.empty()) fail("name", "must not be empty");

    const auto obj = f.find("object");
    if (obj == f.end()) fail("object", "missing required section (the object's cubes and cube_size_m)");
    object(obj->second, "object", s.object);
    if (const auto it = f.find("material"); it != f.end()) material(it->second, "material", s.material);
    opt(f, "gravity_m_per_s2", "", s.gravity_m_per_s2);
    if (const auto it = f.find("fixed"); it != f.end()) {
      for_each(it->second, "fixed", [&](const YAML::Node& n, const std::string& p) {
        const FieldMap g = fields(n, p, {"region"});
        FixedSpec spec;
        spec.region = region(require(g, "region", p), join_key(p, "region"));
        s.fixed.push_back(spec);
      });
    }
    if (const auto it = f.find("prescribed"); it != f.end()) {
      for_each(it->second, "prescribed", [&](const YAML::Node& n, const std::string& p) {
        const FieldMap g = fields(n, p, {"name", "region", "displacement_m", "profile"});
        PrescribedSpec spec;
        spec.name = "prescribed" + std::to_string(s.prescribed.size());
        opt(g, "name", p, spec.name);
        spec.region = region(require(g, "region", p), join_key(p, "region"));
        read(require(g, "displacement_m", p), join_key(p, "displacement_m"), spec.displacement_m);
        if (const auto pr = g.find("profile"); pr != g.end()) profile(pr->second, join_key(p, "profile"), spec.profile);
        s.prescribed.push_back(spec);
      });
    }
    if (const auto it = f.find("loads"); it != f.end()) {
      for_each(it->second, "loads", [&](const YAML::Node& n, const std::string& p) {
        const FieldMap g = fields(n, p, {"name", "region", "total_force_N", "profile"});
        LoadSpec spec;
        spec.name = "load" + std::to_string(s.loads.size());
        opt(g, "name", p, spec.name);
        spec.region = region(require(g, "region", p), join_key(p, "region"));
        read(require(g, "total_force_N", p), join_key(p, "total_force_N"), spec.total_force_N);
        if (const auto pr = g.find("profile"); pr != g.end()) profile(pr->second, join_key(p, "profile"), spec.profile);
        s.loads.push_back(spec);
      });
    }
    if (const auto it = f.find("adaptivity"); it != f.end()) adaptivity(it->second, "adaptivity", s.adaptivity);
    if (const auto it = f.find("integrator"); it != f.end()) integrator(it->second, "integrator", s.integrator);
    if (const auto it = f.find("probes"); it != f.end()) {
      for_each(it->second, "probes", [&](const YAML::Node& n, const std::string& p) {
        const FieldMap g = fields(n, p, {"name", "rest_m"});
        ProbeSpec spec;
        spec.name = "probe" + std::to_string(s.probes.size());
        opt(g, "name", p, spec.name);
        read(require(g, "rest_m", p), join_key(p, "rest_m"), spec.rest_m);
        s.probes.push_back(spec);
      });
    }
    return s;
  }

 private:
  [[noreturn]] void fail(const std::string& path, const std::string& reason) const {
    throw SceneError(source_, path, reason);
  }

  static std::string default_name(const std::string& source) {
    std::string stem = std::filesystem::path(source).stem().string();
    return stem.empty() ? std::string("scene") : stem;
  }

  // The entries of a map, checked against the allowed keys.
  FieldMap fields(const YAML::Node& n, const std::string& path, std::initializer_list<std::string_view> allowed) const {
    if (!n.IsMap()) fail(path, "expected a map with keys " + join_list(allowed) + ", got " + describe(n));
    FieldMap out;
    for (auto it = n.begin(); it != n.end(); ++it) {
      const YAML::Node key = it->first;
      if (!key.IsScalar()) fail(path, "map keys must be plain names, got " + describe(key));
      const std::string& name = key.Scalar();
      const std::string kp = join_key(path, printable_bare(name));
      if (std::find(allowed.begin(), allowed.end(), std::string_view(name)) == allowed.end()) {
        std::string reason = "unknown key " + printable(name);
        if (const auto s = suggest(name, allowed)) reason += " (did you mean '" + std::string(*s) + "'?)";
        fail(kp, reason + "; allowed keys: " + join_list(allowed));
      }
      if (!out.emplace(name, it->second).second) fail(kp, "duplicate key");
    }
    return out;
  }

  const YAML::Node& require(const FieldMap& f, std::string_view key, const std::string& path) const {
    const auto it = f.find(key);
    if (it == f.end()) fail(join_key(path, key), "missing required key");
    return it->second;
  }

  template <class T>
  void opt(const FieldMap& f, std::string_view key, const std::string& path, T& out) const {
    if (const auto it = f.find(key); it != f.end()) read(it->second, join_key(path, key), out);
  }

  template <class F>
  void for_each(const YAML::Node& n, const std::string& path, F&& body) const {
    if (!n.IsSequence()) fail(path, "expected a list, got " + describe(n) + " (write [] for none)");
    std::size_t i = 0;
    for (auto it = n.begin(); it != n.end(); ++it, ++i) body(*it, join_index(path, i));
  }

  void read(const YAML::Node& n, const std::string& path, double& out) const {
    if (!n.IsScalar() || is_quoted(n)) fail(path, "expected a number, got " + describe(n));
    switch (parse_float(n.Scalar(), &out)) {
      case NumberParse::kOk:
        return;
      case NumberParse::kOutOfRange:
        fail(path, "number out of range: " + printable(n.Scalar()));
      case NumberParse::kNotANumber:
        break;
    }
    fail(path, "expected a number, got " + describe(n));
  }

  void read(const YAML::Node& n, const std::string& path, int& out) const {
    if (!n.IsScalar() || is_quoted(n)) fail(path, "expected an integer, got " + describe(n));
    switch (parse_int(n.Scalar(), &out)) {
      case NumberParse::kOk:
        return;
      case NumberParse::kOutOfRange:
        fail(path, "integer out of range: " + printable(n.Scalar()));
      case NumberParse::kNotANumber:
        break;
    }
    fail(path, "expected an integer, got " + describe(n));
  }

  void read(const YAML::Node& n, const std::string& path, bool& out) const {
    if (n.IsScalar() && !is_quoted(n)) {
      const std::string& v = n.Scalar();
      if (v == "true" || v == "True" || v == "TRUE") {
        out = true;
        return;
      }
      if (v == "false" || v == "False" || v == "FALSE") {
        out = false;
        return;
      }
    }
    fail(path, "expected a boolean (true or false), got " + describe(n));
  }

  void read(const YAML::Node& n, const std::string& path, std::string& out) const {
    if (!n.IsScalar()) fail(path, "expected a string, got " + describe(n));
    out = n.Scalar();
  }

  template <class T>
  void read(const YAML::Node& n, const std::string& path, std::array<T, 3>& out) const {
    const char* what = std::is_same_v<T, int> ? "a list of 3 integers" : "a list of 3 numbers";
    if (!n.IsSequence()) fail(path, std::string("expected ") + what + ", got " + describe(n));
    if (n.size() != 3) fail(path, std::string("expected ") + what + ", got " + count_of(n.size(), "item"));
    std::size_t i = 0;
    for (auto it = n.begin(); it != n.end() && i < 3; ++it, ++i) read(*it, join_index(path, i), out[i]);
  }

  template <class E>
  void read_choice(const YAML::Node& n, const std::string& path, Choices<E> choices, E& out) const {
    if (n.IsScalar()) {
      for (const auto& c : choices) {
        if (n.Scalar() == c.first) {
          out = c.second;
          return;
        }
      }
      fail(path, "unknown value " + printable(n.Scalar()) + "; allowed values: " + choice_names(choices));
    }
    fail(path, "expected one of " + choice_names(choices) + ", got " + describe(n));
  }

  template <class E>
  void opt_choice(const FieldMap& f, std::string_view key, const std::string& path, Choices<E> choices, E& out) const {
    if (const auto it = f.find(key); it != f.end()) read_choice(it->second, join_key(path, key), choices, out);
  }

  void object(const YAML::Node& n, const std::string& p, ObjectSpec& o) const {
    const FieldMap f = fields(n, p, {"cubes", "cube_size_m"});
    read(require(f, "cubes", p), join_key(p, "cubes"), o.cubes);
    read(require(f, "cube_size_m", p), join_key(p, "cube_size_m"), o.cube_size_m);
  }

  void material(const YAML::Node& n, const std::string& p, MaterialSpec& m) const {
    const FieldMap f = fields(
        n, p,
        {"youngs_modulus_Pa", "density_kg_per_m3", "stiffness", "damping", "rayleigh_alpha_per_s", "rayleigh_beta_s"});
    opt(f, "youngs_modulus_Pa", p, m.youngs_modulus_Pa);
    opt(f, "density_kg_per_m3", p, m.density_kg_per_m3);
    opt_choice<StiffnessLaw>(f, "stiffness", p, kStiffnessLaws, m.stiffness);
    opt_choice<DampingLaw>(f, "damping", p, kDampingLaws, m.damping);
    opt(f, "rayleigh_alpha_per_s", p, m.rayleigh_alpha_per_s);
    opt(f, "rayleigh_beta_s", p, m.rayleigh_beta_s);
  }

  Region region(const YAML::Node& n, const std::string& p) const {
    const FieldMap f = fields(n, p, {"box", "sphere"});
    const auto box = f.find("box");
    const auto sphere = f.find("sphere");
    if ((box == f.end()) == (sphere == f.end()))
      fail(p,
           std::string("a region has exactly one of 'box' or 'sphere', got ") + (box == f.end() ? "neither" : "both"));
    Region r;
    if (box != f.end()) {
      const std::string bp = join_key(p, "box");
      const FieldMap b = fields(box->second, bp, {"min_m", "max_m"});
      r.kind = Region::Kind::kBox;
      read(require(b, "min_m", bp), join_key(bp, "min_m"), r.min_m);
      read(require(b, "max_m", bp), join_key(bp, "max_m"), r.max_m);
    } else {
      const std::string sp = join_key(p, "sphere");
      const FieldMap s = fields(sphere->second, sp, {"centre_m", "radius_m"});
      r.kind = Region::Kind::kSphere;
      read(require(s, "centre_m", sp), join_key(sp, "centre_m"), r.centre_m);
      read(require(s, "radius_m", sp), join_key(sp, "radius_m"), r.radius_m);
    }
    return r;
  }

  void profile(const YAML::Node& n, const std::string& p, TimeProfile& t) const {
    const FieldMap f = fields(n, p, {"start_s", "ramp_s", "release_s"});
    opt(f, "start_s", p, t.start_s);
    opt(f, "ramp_s", p, t.ramp_s);
    opt(f, "release_s", p, t.release_s);
  }

  void adaptivity(const YAML::Node& n, const std::string& p, AdaptivitySpec& a) const {
    const FieldMap f =
        fields(n, p,
               {"enabled", "criterion", "refine_threshold_Pa", "simplify_factor", "stretch_ratio", "min_depth",
                "max_depth", "every_steps", "max_ops_per_step", "min_age_steps", "midpoint_tolerance"});
    opt(f, "enabled", p, a.enabled);
    opt_choice<RefineCriterion>(f, "criterion", p, kCriteria, a.criterion);
    opt(f, "refine_threshold_Pa", p, a.refine_threshold_Pa);
    opt(f, "simplify_factor", p, a.simplify_factor);
    opt(f, "stretch_ratio", p, a.stretch_ratio);
    opt(f, "min_depth", p, a.min_depth);
    opt(f, "max_depth", p, a.max_depth);
    opt(f, "every_steps", p, a.every_steps);
    opt(f, "max_ops_per_step", p, a.max_ops_per_step);
    opt(f, "min_age_steps", p, a.min_age_steps);
    opt(f, "midpoint_tolerance", p, a.midpoint_tolerance);
  }

  void integrator(const YAML::Node& n, const std::string& p, IntegratorSpec& g) const {
    const FieldMap f =
        fields(n, p, {"kind", "dt_s", "max_substeps", "substep_safety", "cg_tolerance", "cg_max_iterations"});
    opt_choice<IntegratorKind>(f, "kind", p, kIntegrators, g.kind);
    opt(f, "dt_s", p, g.dt_s);
    opt(f, "max_substeps", p, g.max_substeps);
    opt(f, "substep_safety", p, g.substep_safety);
    opt(f, "cg_tolerance", p, g.cg_tolerance);
    opt(f, "cg_max_iterations", p, g.cg_max_iterations);
  }

  const std::string& source_;
};

// ------------------------------------------------------------- validation

class Validator {
 public:
  explicit Validator(const Scene& s) : s_(s) {}

  void run() {
    const ObjectSpec& o = s_.object;
    long long total = 1;
    for (int a = 0; a < 3; ++a) {
      at_least(o.cubes[a], 1, join_index("object.cubes", a));
      total *= o.cubes[a];
      if (total > kMaxTotalCubes)
        fail("object.cubes", "too many cubes (more than " + std::to_string(kMaxTotalCubes) + " in total)");
    }
    positive(o.cube_size_m, "object.cube_size_m");
    for (int a = 0; a < 3; ++a) {
      extent_[a] = o.cubes[a] * o.cube_size_m;
      if (!std::isfinite(extent_[a])) fail("object", "the object's size overflows");
    }
    tolerance_ = 1e-9 * std::max({extent_[0], extent_[1], extent_[2]});

    const MaterialSpec& m = s_.material;
    positive(m.youngs_modulus_Pa, "material.youngs_modulus_Pa");
    positive(m.density_kg_per_m3, "material.density_kg_per_m3");
    enumerator(static_cast<int>(m.stiffness), 2, "material.stiffness");
    enumerator(static_cast<int>(m.damping), 2, "material.damping");
    non_negative(m.rayleigh_alpha_per_s, "material.rayleigh_alpha_per_s");
    non_negative(m.rayleigh_beta_s, "material.rayleigh_beta_s");

    finite(s_.gravity_m_per_s2, "gravity_m_per_s2");

    for (std::size_t i = 0; i < s_.fixed.size(); ++i) region(s_.fixed[i].region, join_index("fixed", i) + ".region");
    for (std::size_t i = 0; i < s_.prescribed.size(); ++i) {
      const PrescribedSpec& p = s_.prescribed[i];
      const std::string kp = join_index("prescribed", i);
      name(p.name, kp + ".name");
      region(p.region, kp + ".region");
      finite(p.displacement_m, kp + ".displacement_m");
      profile(p.profile, kp + ".profile");
    }
    for (std::size_t i = 0; i < s_.loads.size(); ++i) {
      const LoadSpec& l = s_.loads[i];
      const std::string kp = join_index("loads", i);
      name(l.name, kp + ".name");
      region(l.region, kp + ".region");
      finite(l.total_force_N, kp + ".total_force_N");
      profile(l.profile, kp + ".profile");
    }

    const AdaptivitySpec& a = s_.adaptivity;
    enumerator(static_cast<int>(a.criterion), 2, "adaptivity.criterion");
    positive(a.refine_threshold_Pa, "adaptivity.refine_threshold_Pa");
    open_unit(a.simplify_factor, "adaptivity.simplify_factor");
    finite(a.stretch_ratio, "adaptivity.stretch_ratio");
    if (!(a.stretch_ratio > 1.0))
      fail("adaptivity.stretch_ratio", "must be > 1 (got " + fmt_num(a.stretch_ratio) + ")");
    at_least(a.min_depth, 0, "adaptivity.min_depth");
    if (a.max_depth > kMaxDepthLimit)
      fail("adaptivity.max_depth",
           "must be <= " + std::to_string(kMaxDepthLimit) + " (got " + std::to_string(a.max_depth) + ")");
    if (a.min_depth > a.max_depth)
      fail("adaptivity.min_depth",
           "must be <= max_depth (" + std::to_string(a.max_depth) + ") (got " + std::to_string(a.min_depth) + ")");
    at_least(a.every_steps, 1, "adaptivity.every_steps");
    at_least(a.max_ops_per_step, 1, "adaptivity.max_ops_per_step");
    at_least(a.min_age_steps, 0, "adaptivity.min_age_steps");
    positive(a.midpoint_tolerance, "adaptivity.midpoint_tolerance");

    const IntegratorSpec& g = s_.integrator;
    enumerator(static_cast<int>(g.kind), 3, "integrator.kind");
    positive(g.dt_s, "integrator.dt_s");
    if (g.dt_s > 1.0) fail("integrator.dt_s", "must be <= 1 s (got " + fmt_num(g.dt_s) + ")");
    at_least(g.max_substeps, 1, "integrator.max_substeps");
    finite(g.substep_safety, "integrator.substep_safety");
    if (!(g.substep_safety > 0.0 && g.substep_safety <= 1.0))
      fail("integrator.substep_safety", "must be in (0, 1] (got " + fmt_num(g.substep_safety) + ")");
    open_unit(g.cg_tolerance, "integrator.cg_tolerance");
    at_least(g.cg_max_iterations, 1, "integrator.cg_max_iterations");

    for (std::size_t i = 0; i < s_.probes.size(); ++i) {
      const ProbeSpec& p = s_.probes[i];
      const std::string kp = join_index("probes", i);
      name(p.name, kp + ".name");
      finite(p.rest_m, kp + ".rest_m");
      for (int ax = 0; ax < 3; ++ax)
        if (p.rest_m[ax] < -tolerance_ || p.rest_m[ax] > extent_[ax] + tolerance_)
          fail(kp + ".rest_m", "the point lies outside the object " + object_box() + " (a typo?)");
    }

    unique_names(s_.prescribed, "prescribed");
    unique_names(s_.loads, "loads");
    unique_names(s_.probes, "probes");
  }

 private:
  [[noreturn]] void fail(const std::string& path, const std::string& reason) const {
    throw SceneError(s_.source, path, reason);
  }

  void finite(double v, const std::string& path) const {
    if (!std::isfinite(v)) fail(path, "must be a finite number (got " + fmt_num(v) + ")");
  }
  void finite(const Vec3& v, const std::string& path) const {
    for (std::size_t i = 0; i < 3; ++i) finite(v[i], join_index(path, i));
  }
  void positive(double v, const std::string& path) const {
    finite(v, path);
    if (!(v > 0.0)) fail(path, "must be > 0 (got " + fmt_num(v) + ")");
  }
  void non_negative(double v, const std::string& path) const {
    finite(v, path);
    if (!(v >= 0.0)) fail(path, "must be >= 0 (got " + fmt_num(v) + ")");
  }
  void open_unit(double v, const std::string& path) const {
    finite(v, path);
    if (!(v > 0.0 && v < 1.0)) fail(path, "must be in (0, 1) (got " + fmt_num(v) + ")");
  }
  void at_least(int v, int lo, const std::string& path) const {
    if (v < lo) fail(path, "must be >= " + std::to_string(lo) + " (got " + std::to_string(v) + ")");
  }
  void enumerator(int v, int count, const std::string& path) const {
    if (v < 0 || v >= count) fail(path, "invalid enumerator value " + std::to_string(v));
  }

  // Names label outputs (probe columns, recorded series): keep them short and plain.
  void name(const std::string& n, const std::string& path) const {
    if (n.empty()) fail(path, "must not be empty");
    if (n.size() > kMaxNameLength)
      fail(path,
           "too long (" + std::to_string(n.size()) + " characters, at most " + std::to_string(kMaxNameLength) + ")");
    for (const char ch : n) {
      const bool ok =
          (ch >= 'a' && ch <= 'z') || (ch >= 'A' && ch <= 'Z') || is_digit(ch) || ch == '_' || ch == '-' || ch == '.';
      if (!ok) fail(path, "bad name " + printable(n) + ": use only letters, digits, '_', '-' and '.'");
    }
  }

  std::string object_box() const {
    return "box [0, " + fmt_num(extent_[0]) + "] x [0, " + fmt_num(extent_[1]) + "] x [0, " + fmt_num(extent_[2]) +
           "] m";
  }

  void region(const Region& r, const std::string& path) const {
    switch (r.kind) {
      case Region::Kind::kBox: {
        const std::string bp = path + ".box";
        finite(r.min_m, bp + ".min_m");
        finite(r.max_m, bp + ".max_m");
        for (std::size_t a = 0; a < 3; ++a)
          if (r.min_m[a] > r.max_m[a])
            fail(bp, "min_m[" + std::to_string(a) + "] > max_m[" + std::to_string(a) + "] (" + fmt_num(r.min_m[a]) +
                         " > " + fmt_num(r.max_m[a]) + ")");
        for (std::size_t a = 0; a < 3; ++a)
          if (r.max_m[a] < -tolerance_ || r.min_m[a] > extent_[a] + tolerance_)
            fail(path, "the box lies entirely outside the object " + object_box() + " (a typo?)");
        return;
      }
      case Region::Kind::kSphere: {
        const std::string sp = path + ".sphere";
        finite(r.centre_m, sp + ".centre_m");
        non_negative(r.radius_m, sp + ".radius_m");
        double d2 = 0.0;
        for (std::size_t a = 0; a < 3; ++a) {
          const double c = r.centre_m[a];
          const double d = c < 0.0 ? -c : (c > extent_[a] ? c - extent_[a] : 0.0);
          d2 += d * d;
        }
        const double reach = r.radius_m + tolerance_;
        if (d2 > reach * reach)
          fail(path, "the sphere lies entirely outside the object " + object_box() + " (a typo?)");
        return;
      }
    }
    fail(path, "invalid region kind " + std::to_string(static_cast<int>(r.kind)));
  }

  void profile(const TimeProfile& t, const std::string& path) const {
    finite(t.start_s, path + ".start_s");
    if (t.start_s < 0.0) fail(path + ".start_s", "must be >= 0 (got " + fmt_num(t.start_s) + ")");
    non_negative(t.ramp_s, path + ".ramp_s");
    if (std::isnan(t.release_s)) fail(path + ".release_s", "must be a number or .inf (got nan)");
    if (!(t.release_s > t.start_s))
      fail(path + ".release_s", "must be > start_s (" + fmt_num(t.start_s) + ") (got " + fmt_num(t.release_s) + ")");
  }

  template <class T>
  void unique_names(const std::vector<T>& items, const std::string& list) const {
    std::map<std::string_view, std::size_t> seen;
    for (std::size_t i = 0; i < items.size(); ++i) {
      const auto [it, fresh] = seen.emplace(items[i].name, i);
      if (!fresh)
        fail(join_index(list, i) + ".name",
             "duplicate name " + printable(items[i].name) + " (also " + join_index(list, it->second) + ".name)");
    }
  }

  const Scene& s_;
  std::array<double, 3> extent_{};
  double tolerance_ = 0.0;
};

// ---------------------------------------------------------------- documents

std::string syntax_error(const YAML::Exception& e) {
  std::string out = "YAML syntax error";
  if (!e.mark.is_null())
    out += " at line " + std::to_string(e.mark.line + 1) + ", column " + std::to_string(e.mark.column + 1);
  return out + ": " + (e.msg.empty() ? std::string(e.what()) : e.msg);
}

std::string at_mark(const YAML::Mark& m) {
  return "line " + std::to_string(m.line + 1) + ", column " + std::to_string(m.column + 1);
}

// Records where each document starts; ignores everything else.
class DocumentStarts : public YAML::EventHandler {
 public:
  void OnDocumentStart(const YAML::Mark& mark) override { starts.push_back(mark); }
  void OnDocumentEnd() override {}
  void OnNull(const YAML::Mark&, YAML::anchor_t) override {}
  void OnAlias(const YAML::Mark&, YAML::anchor_t) override {}
  void OnScalar(const YAML::Mark&, const std::string&, YAML::anchor_t, const std::string&) override {}
  void OnSequenceStart(const YAML::Mark&, const std::string&, YAML::anchor_t, YAML::EmitterStyle::value) override {}
  void OnSequenceEnd() override {}
  void OnMapStart(const YAML::Mark&, const std::string&, YAML::anchor_t, YAML::EmitterStyle::value) override {}
  void OnMapEnd() override {}

  std::vector<YAML::Mark> starts;
};

// The one document in `text`, or a SceneError. `what` prefixes messages.
//
// Not YAML::LoadAll: in yaml-cpp 0.7 it never returns for some malformed
// input (e.g. "!x\n,"), appending empty documents until memory runs out
// (jbeder/yaml-cpp#1040, fixed upstream by PR #1319). Instead the parser is
// asked for at most two documents, then YAML::Load builds the first.
YAML::Node load_document(const std::string& text, const std::string& source, const std::string& key_path,
                         const std::string& what, bool allow_empty) {
  const auto error = [&](const std::string& reason) { return SceneError(source, key_path, what + reason); };
  try {
    std::istringstream stream(text);
    YAML::Parser parser(stream);
    DocumentStarts starts;
    if (parser.HandleNextDocument(starts) && parser.HandleNextDocument(starts) && starts.starts.size() >= 2) {
      const YAML::Mark& second = starts.starts[1];
      const bool explicit_start = second.pos >= 0 && static_cast<std::size_t>(second.pos) < text.size() &&
                                  text.compare(static_cast<std::size_t>(second.pos), 3, "---") == 0;
      if (explicit_start)
        throw error("found a second YAML document at " + at_mark(second) + "; a scene is exactly one document");
      throw error("YAML syntax error at " + at_mark(second) + ": unexpected content after the document");
    }
    const YAML::Node root = YAML::Load(text);
    if (!root.IsDefined() || root.IsNull()) {
      if (allow_empty) return YAML::Node();
      throw error("empty document: a scene needs at least an 'object' section");
    }
    return root;
  } catch (const YAML::DeepRecursion& e) {
    throw error("YAML nesting too deep (the limit is " + std::to_string(e.depth()) + " levels)");
  } catch (const YAML::Exception& e) {
    throw error(syntax_error(e));
  }
}

// ---------------------------------------------------------------- overrides

struct PathPart {
  bool is_index = false;
  std::string key;
  std::size_t index = 0;
};

struct Override {
  std::string text;  // as given, for messages
  std::string path;  // canonical key path
  std::vector<PathPart> parts;
  YAML::Node value;
};

bool is_key_char(char c) {
  return (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || is_digit(c) || c == '_' || c == '-';
}

std::string trim(std::string_view s) {
  const auto b = s.find_first_not_of(" \t");
  if (b == std::string_view::npos) return {};
  const auto e = s.find_last_not_of(" \t");
  return std::string(s.substr(b, e - b + 1));
}

Override parse_override(const std::string& text, const std::string& source) {
  const std::string shown = "--set " + printable(text);
  const auto eq = text.find('=');
  if (eq == std::string::npos)
    throw SceneError(source, "", "malformed override " + shown + ": expected key.path=value (no '=' found)");
  Override ov;
  ov.text = text;
  const std::string key = trim(std::string_view(text).substr(0, eq));
  const auto bad_path = [&](const std::string& why) {
    return SceneError(source, "", "malformed override " + shown + ": bad key path " + printable(key) + ": " + why);
  };
  if (key.empty()) throw bad_path("it is empty");
  std::size_t i = 0;
  while (i < key.size()) {
    if (key[i] == '[') {
      if (ov.parts.empty()) throw bad_path("it must start with a key");
      const std::size_t close = key.find(']', i);
      if (close == std::string::npos) throw bad_path("missing ']'");
      const std::string_view digits(key.data() + i + 1, close - i - 1);
      if (digits.empty() || !std::all_of(digits.begin(), digits.end(), is_digit))
        throw bad_path("a list index must be a non-negative integer");
      PathPart p;
      p.is_index = true;
      const auto [ptr, ec] = std::from_chars(digits.data(), digits.data() + digits.size(), p.index);
      if (ec != std::errc() || ptr != digits.data() + digits.size()) throw bad_path("list index out of range");
      ov.parts.push_back(p);
      i = close + 1;
      if (i < key.size() && key[i] != '.' && key[i] != '[') throw bad_path("expected '.' or '[' after ']'");
    } else {
      if (key[i] == '.') {
        if (ov.parts.empty()) throw bad_path("it must start with a key");
        ++i;
      }
      std::size_t j = i;
      while (j < key.size() && is_key_char(key[j])) ++j;
      if (j == i) throw bad_path("expected a key name at position " + std::to_string(i + 1));
      PathPart p;
      p.key = key.substr(i, j - i);
      ov.parts.push_back(p);
      i = j;
    }
  }
  for (const PathPart& p : ov.parts) ov.path = p.is_index ? join_index(ov.path, p.index) : join_key(ov.path, p.key);
  ov.value = load_document(text.substr(eq + 1), source, ov.path, shown + ": the value is not valid YAML: ", true);
  return ov;
}

// Returns a copy of `node` with parts[i..] set to ov.value. Only the maps and
// lists on the path are copied (shallowly), so anchors/aliases elsewhere in the
// tree are not affected.
YAML::Node set_path(const YAML::Node& node, bool present, const Override& ov, std::size_t i, const std::string& done,
                    const std::string& source) {
  if (i == ov.parts.size()) return ov.value;
  const PathPart& part = ov.parts[i];
  const std::string shown = "--set " + printable(ov.text);
  if (part.is_index) {
    const std::string here = join_index(done, part.index);
    if (!present || !node.IsSequence())
      throw SceneError(
          source, done,
          shown + ": cannot index " + (present ? describe(node) : std::string("a missing key")) + ", it is not a list");
    if (part.index >= node.size())
      throw SceneError(source, here,
                       shown + ": list index out of range (the list has " + count_of(node.size(), "item") + ")");
    YAML::Node out(YAML::NodeType::Sequence);
    std::size_t j = 0;
    for (auto it = node.begin(); it != node.end(); ++it, ++j)
      out.push_back(j == part.index ? set_path(*it, true, ov, i + 1, here, source) : YAML::Node(*it));
    return out;
  }
  const std::string here = join_key(done, part.key);
  if (present && !node.IsNull() && !node.IsMap())
    throw SceneError(source, done.empty() ? here : done,
                     shown + ": cannot set key '" + part.key + "' inside " + describe(node) + ", it is not a map");
  YAML::Node out(YAML::NodeType::Map);
  bool replaced = false;
  if (present && node.IsMap()) {
    for (auto it = node.begin(); it != node.end(); ++it) {
      if (!replaced && it->first.IsScalar() && it->first.Scalar() == part.key) {
        out.force_insert(it->first, set_path(it->second, true, ov, i + 1, here, source));
        replaced = true;
      } else {
        out.force_insert(it->first, it->second);
      }
    }
  }
  if (!replaced) out.force_insert(YAML::Node(part.key), set_path(YAML::Node(), false, ov, i + 1, here, source));
  return out;
}

// a and b name the same node, or one lies inside the other.
bool paths_related(const std::string& a, const std::string& b) {
  if (a.empty() || b.empty()) return false;
  const std::string& s = a.size() <= b.size() ? a : b;
  const std::string& l = a.size() <= b.size() ? b : a;
  if (l.compare(0, s.size(), s) != 0) return false;
  return l.size() == s.size() || l[s.size()] == '.' || l[s.size()] == '[';
}

Scene build(const std::string& yaml_text, const std::string& source, const std::vector<std::string>& overrides) {
  try {
    YAML::Node root = load_document(yaml_text, source, "", "", false);
    std::vector<Override> applied;
    applied.reserve(overrides.size());
    for (const std::string& text : overrides) {
      applied.push_back(parse_override(text, source));
      root = set_path(root, true, applied.back(), 0, "", source);
    }
    try {
      Scene s = Converter(source).scene(root);
      validate_scene(s);
      return s;
    } catch (const SceneError& e) {
      for (auto it = applied.rbegin(); it != applied.rend(); ++it)
        if (paths_related(it->path, e.key_path()))
          throw SceneError(e.source(), e.key_path(), e.reason() + " (set by --set " + printable(it->text) + ")");
      throw;
    }
  } catch (const YAML::Exception& e) {
    // Not expected (the converter only reads nodes it has checked), but a
    // yaml-cpp exception must never escape as anything but a SceneError.
    throw SceneError(source, "", std::string("YAML error: ") + e.what());
  }
}

std::string read_file(const std::string& path) {
  namespace fs = std::filesystem;
  std::error_code ec;
  const fs::file_status st = fs::status(path, ec);
  if (st.type() == fs::file_type::not_found) throw SceneError(path, "", "cannot read scene file: no such file");
  if (ec) throw SceneError(path, "", "cannot read scene file: " + ec.message());
  if (fs::is_directory(st)) throw SceneError(path, "", "cannot read scene file: it is a directory");
  if (!fs::is_regular_file(st)) throw SceneError(path, "", "cannot read scene file: not a regular file");
  const std::uintmax_t size = fs::file_size(path, ec);
  if (!ec && size > kMaxSceneFileBytes)
    throw SceneError(path, "", "cannot read scene file: " + std::to_string(size) + " bytes is too large for a scene");
  std::ifstream in(path, std::ios::binary);
  if (!in) throw SceneError(path, "", std::string("cannot read scene file: ") + std::strerror(errno));
  std::string text;
  char buf[65536];
  while (in.read(buf, sizeof buf) || in.gcount() > 0) {
    text.append(buf, static_cast<std::size_t>(in.gcount()));
    if (text.size() > kMaxSceneFileBytes) throw SceneError(path, "", "cannot read scene file: too large for a scene");
  }
  if (in.bad()) throw SceneError(path, "", "cannot read scene file: read error");
  return text;
}

}  // namespace

void validate_scene(const Scene& s) { Validator(s).run(); }

Scene parse_scene(const std::string& yaml_text, const std::string& source_name) {
  return build(yaml_text, source_name, {});
}

Scene parse_scene_with_overrides(const std::string& yaml_text, const std::string& source_name,
                                 const std::vector<std::string>& overrides) {
  return build(yaml_text, source_name, overrides);
}

Scene load_scene_file(const std::string& path) { return build(read_file(path), path, {}); }

Scene load_scene_file_with_overrides(const std::string& path, const std::vector<std::string>& overrides) {
  return build(read_file(path), path, overrides);
}

}  // namespace tissue::scene
