// Shared machinery of the YAML loaders (scene files, the daemon config):
// strict scalar parsing, key checking with typo suggestions, one-document
// loading that survives yaml-cpp 0.7's bugs, `--set key.path=value`
// overrides and bounded file reading.
//
// Internal to the loaders: this header includes yaml-cpp, so public headers
// (scene_yaml.hpp, daemon_config_yaml.hpp) never include it. Every function
// here reports bad input as a PathError; each loader translates that into its
// own public error type (SceneError, ConfigError) at its boundary.
#pragma once

#include <cmath>

#include <yaml-cpp/yaml.h>

#include <array>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <initializer_list>
#include <map>
#include <memory>
#include <optional>
#include <span>
#include <stdexcept>
#include <string>
#include <string_view>
#include <type_traits>
#include <utility>
#include <vector>

namespace tissue::yaml_util {

// "<source>: <key_path>: <reason>" (key_path may be empty; what() then reads
// "<source>: <reason>", and `unnamed` stands in for an empty source). The
// parts stay readable for callers that re-raise or report them.
class KeyPathError : public std::runtime_error {
 public:
  const std::string& source() const noexcept { return parts_->source; }
  const std::string& key_path() const noexcept { return parts_->key_path; }
  const std::string& reason() const noexcept { return parts_->reason; }

 protected:
  KeyPathError(const std::string& source, const std::string& key_path, const std::string& reason, const char* unnamed);

 private:
  struct Parts {
    std::string source, key_path, reason;
  };
  std::shared_ptr<const Parts> parts_;  // shared: copying an exception must not throw
};

// What the shared machinery throws; each loader re-raises it as its own
// DocumentError type at its boundary.
class PathError : public KeyPathError {
 public:
  PathError(const std::string& source, const std::string& key_path, const std::string& reason)
      : KeyPathError(source, key_path, reason, "<yaml>") {}
};

// ---------------------------------------------------------------- formatting

std::string fmt_num(double v);                   // shortest round-trip text; nan, inf, -inf
std::string printable_bare(std::string_view s);  // printable ASCII, \xNN otherwise, at most 40 chars
std::string printable(std::string_view s);       // the same in single quotes
// An override "key.path=value" in single quotes: the key up to 120
// characters (a key path is what the user must find), the value up to 40.
std::string printable_override(std::string_view text);
using KeyList = std::span<const std::string_view>;
std::string join_list(KeyList items);
std::string join_key(const std::string& path, std::string_view key);
std::string join_index(const std::string& path, std::size_t i);
std::string count_of(std::size_t n, const char* noun);
// The allowed key closest to a short typo, if any is close.
std::optional<std::string_view> suggest(std::string_view key, KeyList allowed);

// ----------------------------------------------------------------- scalars

bool is_digit(char c);
// Quoted scalars ("5", '5') and !!str are strings, never numbers or booleans.
bool is_quoted(const YAML::Node& n);
// A node as a message shows it: "null", "a list", "a map", 'text'.
std::string describe(const YAML::Node& n);
// The kind of node without its text: for a whole document that is not a
// map. The control socket's load_scene reads files as the daemon's user, so
// quoting the start of a file that is not a scene (say /etc/passwd) would
// show a client what it may not read itself.
std::string describe_kind(const YAML::Node& n);
// A key worth echoing: 1..64 letters, digits, '_' or '-'.
bool plain_name(std::string_view s);

enum class NumberParse { kOk, kNotANumber, kOutOfRange };
// YAML 1.2 core-schema decimal numbers plus the .inf/.nan spellings.
NumberParse parse_float(std::string_view s, double* out);
// Decimal integers that fit an int.
NumberParse parse_int(std::string_view s, int* out);

// ---------------------------------------------------------- typed reading

using FieldMap = std::map<std::string, YAML::Node, std::less<>>;

template <class E>
using Choices = std::span<const std::pair<std::string_view, E>>;

template <class E>
std::string choice_names(Choices<E> choices) {
  std::string out;
  for (const auto& c : choices) {
    if (!out.empty()) out += ", ";
    out += c.first;
  }
  return out;
}

// Reads YAML nodes into plain values; every failure is a PathError naming
// `source` and the key path. Loaders derive their converters from it.
class Reader {
 public:
  explicit Reader(std::string source) : source_(std::move(source)) {}

  [[noreturn]] void fail(const std::string& path, const std::string& reason) const;

  // The entries of a map, checked against the allowed keys (unknown keys get
  // a "did you mean" and the list of allowed ones; duplicates are errors).
  FieldMap fields(const YAML::Node& n, const std::string& path, KeyList allowed) const;
  FieldMap fields(const YAML::Node& n, const std::string& path, std::initializer_list<std::string_view> allowed) const {
    return fields(n, path, KeyList(allowed.begin(), allowed.size()));
  }
  const YAML::Node& require(const FieldMap& f, std::string_view key, const std::string& path) const;

  template <class T>
  void opt(const FieldMap& f, std::string_view key, const std::string& path, T& out) const {
    if (const auto it = f.find(key); it != f.end()) read(it->second, join_key(path, key), out);
  }

  // body(item, "path[i]") for every item of a list.
  template <class F>
  void for_each(const YAML::Node& n, const std::string& path, F&& body) const {
    if (!n.IsSequence()) fail(path, "expected a list, got " + describe(n) + " (write [] for none)");
    std::size_t i = 0;
    for (auto it = n.begin(); it != n.end(); ++it, ++i) body(*it, join_index(path, i));
  }

  void read(const YAML::Node& n, const std::string& path, double& out) const;
  void read(const YAML::Node& n, const std::string& path, int& out) const;
  void read(const YAML::Node& n, const std::string& path, bool& out) const;
  void read(const YAML::Node& n, const std::string& path, std::string& out) const;
  // A non-negative integer (sizes, byte counts).
  void read(const YAML::Node& n, const std::string& path, std::size_t& out) const;

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

  const std::string& source() const noexcept { return source_; }

 protected:
  std::string source_;
};

// ---------------------------------------------------------------- documents

// What the document is, for messages: kind "scene" gives "a scene is exactly
// one document"; empty_hint completes "empty document: <hint>".
struct DocumentKind {
  std::string kind;
  std::string empty_hint;
};

// The most nodes (scalars, lists, maps and aliases) a document may have.
// yaml-cpp builds the whole tree before a loader can check a list's length:
// a 3 MiB flow list of zeros took 6.6 s and 750 MB to build, and the daemon
// loads scenes on the control thread that feeds systemd's 5 s watchdog. A
// scene or daemon config is a few hundred nodes; one with every list at its
// limit (1000 regions a list, 1000 probes), every key written, 83,018.
inline constexpr std::size_t kMaxDocumentNodes = 100'000;

// The one YAML document in `text`. `prefix` starts every reason; an empty
// document is an error unless allow_empty (then an undefined node). More than
// kMaxDocumentNodes nodes is an error, found before the tree is built.
YAML::Node load_document(const std::string& text, const std::string& source, const std::string& key_path,
                         const std::string& prefix, const DocumentKind& doc, bool allow_empty);

// One "key.path=value" override, parsed.
struct Override {
  struct Part {
    bool is_index = false;
    std::string key;
    std::size_t index = 0;
  };
  std::string text;  // as given, for messages
  std::string path;  // canonical key path
  std::vector<Part> parts;
  YAML::Node value;
};

Override parse_override(const std::string& text, const std::string& source, const DocumentKind& doc);
// Canonical key path `inner` names the node `outer` names or one inside it
// ("a.b[2].c" lies within "a.b"; "a.bc" does not). An empty path names nothing.
bool path_within(const std::string& inner, const std::string& outer);
// A copy of `root` with the override applied (missing maps on the path are
// created; list indices must exist).
YAML::Node apply_override(const YAML::Node& root, const Override& ov, const std::string& source);

// The document in `text` with `overrides` applied in order.
struct Document {
  YAML::Node root;
  std::vector<Override> overrides;
};
Document load_with_overrides(const std::string& text, const std::string& source,
                             const std::vector<std::string>& overrides, const DocumentKind& doc);

// `reason`, plus " (set by the override '...')" when the latest override
// whose path contains or lies inside `key_path` probably caused the error.
// Overrides come from a command line's --set and from the control socket's
// `set` alike, so the words name neither ("set by --set" misled a client).
std::string blame_override(const std::vector<Override>& overrides, const std::string& key_path,
                           const std::string& reason);

// The whole file; missing, unreadable, not regular, or larger than max_bytes
// is a PathError "cannot read <what>: ..." naming the path.
std::string read_text_file(const std::string& path, std::uintmax_t max_bytes, const std::string& what);

// An error in a YAML document, naming the file, the key path and the reason;
// the scene and daemon-config errors are this with their own type.
class DocumentError : public KeyPathError {
 public:
  DocumentError(const std::string& source, const std::string& key_path, const std::string& reason, const char* unnamed)
      : KeyPathError(source, key_path, reason, unnamed) {}
};

// The loaders' boundary: `convert(root)` over the document in `text` with
// `overrides` applied. Whatever goes wrong leaves as an Error (the loader's
// public DocumentError type) naming the file and key path, with the --set
// that probably caused it; a yaml-cpp exception never escapes as anything else.
template <class Error, class Convert>
auto convert_document(const std::string& text, const std::string& source, const std::vector<std::string>& overrides,
                      const DocumentKind& kind, Convert&& convert) -> decltype(convert(YAML::Node())) {
  try {
    const Document doc = load_with_overrides(text, source, overrides, kind);
    try {
      return convert(doc.root);
    } catch (const Error& e) {
      throw Error(e.source(), e.key_path(), blame_override(doc.overrides, e.key_path(), e.reason()));
    } catch (const PathError& e) {
      throw Error(e.source(), e.key_path(), blame_override(doc.overrides, e.key_path(), e.reason()));
    }
  } catch (const PathError& e) {
    throw Error(e.source(), e.key_path(), e.reason());
  } catch (const YAML::Exception& e) {
    // Not expected (the converters only read nodes they have checked).
    throw Error(source, "", std::string("YAML error: ") + e.what());
  }
}

// read_text_file with its PathError as the loader's Error.
template <class Error>
std::string read_text_file_as(const std::string& path, std::uintmax_t max_bytes, const std::string& what) {
  try {
    return read_text_file(path, max_bytes, what);
  } catch (const PathError& e) {
    throw Error(e.source(), e.key_path(), e.reason());
  }
}

// Value checks shared by the scene and daemon-config validators (CRTP): each
// reports through the derived class's fail(path, reason), which throws that
// document's error type naming the file.
template <typename Derived>
class ValueChecks {
 protected:
  void finite(double v, const std::string& path) const {
    if (!std::isfinite(v)) self().fail(path, "must be a finite number (got " + fmt_num(v) + ")");
  }
  void finite(const std::array<double, 3>& v, const std::string& path) const {
    for (std::size_t i = 0; i < 3; ++i) finite(v[i], join_index(path, i));
  }
  void positive(double v, const std::string& path) const {
    finite(v, path);
    if (!(v > 0.0)) self().fail(path, "must be > 0 (got " + fmt_num(v) + ")");
  }
  void non_negative(double v, const std::string& path) const {
    finite(v, path);
    if (!(v >= 0.0)) self().fail(path, "must be >= 0 (got " + fmt_num(v) + ")");
  }
  // A bound where a value beyond it would hang a thread or overflow a clock
  // (a ramp of 1e308 s, a period past int64 nanoseconds): `why` says which.
  void at_most(double v, double max, const std::string& path, const std::string& why) const {
    if (v > max) self().fail(path, "must be <= " + fmt_num(max) + " (got " + fmt_num(v) + "): " + why);
  }
  void at_least(double v, double min, const std::string& path, const std::string& why) const {
    if (v < min) self().fail(path, "must be >= " + fmt_num(min) + " (got " + fmt_num(v) + "): " + why);
  }

 private:
  const Derived& self() const { return static_cast<const Derived&>(*this); }
};

}  // namespace tissue::yaml_util
