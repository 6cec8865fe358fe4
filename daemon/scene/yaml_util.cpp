#include "scene/yaml_util.hpp"

#include <yaml-cpp/depthguard.h>
#include <yaml-cpp/eventhandler.h>

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <charconv>
#include <climits>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <sstream>
#include <system_error>

#include "util/text.hpp"

namespace tissue::yaml_util {

namespace {

// "<source>: <key_path>: <reason>", `fallback_source` for an empty source.
std::string compose_what(const std::string& source, const std::string& key_path, const std::string& reason,
                         const char* fallback_source) {
  std::string out = source.empty() ? std::string(fallback_source) : source;
  out += ": ";
  if (!key_path.empty()) {
    out += key_path;
    out += ": ";
  }
  out += reason;
  return out;
}

}  // namespace

KeyPathError::KeyPathError(const std::string& source, const std::string& key_path, const std::string& reason,
                           const char* unnamed)
    : std::runtime_error(compose_what(source, key_path, reason, unnamed)),
      parts_(std::make_shared<const Parts>(Parts{source, key_path, reason})) {}

// ---------------------------------------------------------------- formatting

std::string fmt_num(double v) { return util::number_text(v); }

namespace {
std::string printable_up_to(std::string_view s, std::size_t max_chars) {
  std::string out;
  std::size_t n = 0;
  for (const char ch : s) {
    if (n++ == max_chars) {
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

}  // namespace

std::string printable_bare(std::string_view s) { return printable_up_to(s, 40); }

std::string printable(std::string_view s) { return "'" + printable_bare(s) + "'"; }

std::string printable_override(std::string_view text) {
  const std::size_t eq = text.find('=');
  if (eq == std::string_view::npos) return printable(text);
  return "'" + printable_up_to(text.substr(0, eq), 120) + "=" + printable_bare(text.substr(eq + 1)) + "'";
}

bool plain_name(std::string_view s) {
  if (s.empty() || s.size() > 64) return false;
  for (const char c : s)
    if (!(std::isalnum(static_cast<unsigned char>(c)) || c == '_' || c == '-')) return false;
  return true;
}

std::string join_list(KeyList items) {
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

namespace {

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

}  // namespace

std::optional<std::string_view> suggest(std::string_view key, KeyList allowed) {
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

std::string describe_kind(const YAML::Node& n) {
  if (n.IsScalar()) return "a line of text (contents not shown)";
  return describe(n);
}

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

// ---------------------------------------------------------- typed reading

void Reader::fail(const std::string& path, const std::string& reason) const { throw PathError(source_, path, reason); }

FieldMap Reader::fields(const YAML::Node& n, const std::string& path, KeyList allowed) const {
  if (!n.IsMap()) fail(path, "expected a map with keys " + join_list(allowed) + ", got " + describe(n));
  FieldMap out;
  for (auto it = n.begin(); it != n.end(); ++it) {
    const YAML::Node key = it->first;
    if (!key.IsScalar()) fail(path, "map keys must be plain names, got " + describe(key));
    const std::string& name = key.Scalar();
    // yaml-cpp reads a merge key as the plain key "<<" (no merging): say so.
    if (name == "<<")
      fail(join_key(path, "<<"),
           "YAML merge keys (<<: *anchor) are not supported; write the keys out (anchors "
           "and aliases of whole values are)");
    // A key that is no plain name is not echoed: a file that is not a scene
    // (an /etc/shadow line reads as a YAML key) must not come back through
    // the control socket, which reads files with the daemon's rights.
    if (!plain_name(name))
      fail(join_key(path, "<key not shown>"),
           "unknown key that is not a plain name (letters, digits, '_', '-'; up to 64), not shown; allowed keys: " +
               join_list(allowed));
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

const YAML::Node& Reader::require(const FieldMap& f, std::string_view key, const std::string& path) const {
  const auto it = f.find(key);
  if (it == f.end()) fail(join_key(path, key), "missing required key");
  return it->second;
}

void Reader::read(const YAML::Node& n, const std::string& path, double& out) const {
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

void Reader::read(const YAML::Node& n, const std::string& path, int& out) const {
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

void Reader::read(const YAML::Node& n, const std::string& path, std::size_t& out) const {
  if (!n.IsScalar() || is_quoted(n)) fail(path, "expected a non-negative integer, got " + describe(n));
  std::string_view t = n.Scalar();
  if (!t.empty() && t[0] == '+') t.remove_prefix(1);
  if (t.empty() || !std::all_of(t.begin(), t.end(), is_digit)) {
    if (!t.empty() && t[0] == '-' && t.size() > 1 && std::all_of(t.begin() + 1, t.end(), is_digit))
      fail(path, "must be >= 0 (got " + printable_bare(n.Scalar()) + ")");
    fail(path, "expected a non-negative integer, got " + describe(n));
  }
  const auto [ptr, ec] = std::from_chars(t.data(), t.data() + t.size(), out);
  if (ec == std::errc::result_out_of_range) fail(path, "integer out of range: " + printable(n.Scalar()));
  if (ec != std::errc() || ptr != t.data() + t.size())
    fail(path, "expected a non-negative integer, got " + describe(n));
}

void Reader::read(const YAML::Node& n, const std::string& path, bool& out) const {
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

void Reader::read(const YAML::Node& n, const std::string& path, std::string& out) const {
  if (!n.IsScalar()) fail(path, "expected a string, got " + describe(n));
  out = n.Scalar();
}

// ---------------------------------------------------------------- documents

namespace {

std::string syntax_error(const YAML::Exception& e) {
  std::string out = "YAML syntax error";
  if (!e.mark.is_null())
    out += " at line " + std::to_string(e.mark.line + 1) + ", column " + std::to_string(e.mark.column + 1);
  return out + ": " + (e.msg.empty() ? std::string(e.what()) : e.msg);
}

std::string at_mark(const YAML::Mark& m) {
  return "line " + std::to_string(m.line + 1) + ", column " + std::to_string(m.column + 1);
}

// Thrown by DocumentStarts past kMaxDocumentNodes: stops the parser there.
struct TooManyNodes {};

// Records where each document starts and counts the nodes; ignores the rest.
class DocumentStarts : public YAML::EventHandler {
 public:
  void OnDocumentStart(const YAML::Mark& mark) override { starts.push_back(mark); }
  void OnDocumentEnd() override {}
  void OnNull(const YAML::Mark&, YAML::anchor_t) override { count(); }
  void OnAlias(const YAML::Mark&, YAML::anchor_t) override { count(); }
  void OnScalar(const YAML::Mark&, const std::string&, YAML::anchor_t, const std::string&) override { count(); }
  void OnSequenceStart(const YAML::Mark&, const std::string&, YAML::anchor_t, YAML::EmitterStyle::value) override {
    count();
  }
  void OnSequenceEnd() override {}
  void OnMapStart(const YAML::Mark&, const std::string&, YAML::anchor_t, YAML::EmitterStyle::value) override {
    count();
  }
  void OnMapEnd() override {}

  std::vector<YAML::Mark> starts;

 private:
  void count() {
    if (++nodes_ > kMaxDocumentNodes) throw TooManyNodes{};
  }
  std::size_t nodes_ = 0;
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

// Returns a copy of `node` with parts[i..] set to ov.value. Only the maps and
// lists on the path are copied (shallowly), so anchors/aliases elsewhere in the
// tree are not affected.
YAML::Node set_path(const YAML::Node& node, bool present, const Override& ov, std::size_t i, const std::string& done,
                    const std::string& source) {
  if (i == ov.parts.size()) return ov.value;
  const Override::Part& part = ov.parts[i];
  // Overrides come from --set and from the control socket's `set`: the
  // words name neither.
  const std::string shown = "the override " + printable_override(ov.text);
  if (part.is_index) {
    const std::string here = join_index(done, part.index);
    if (!present || !node.IsSequence())
      throw PathError(
          source, done,
          shown + ": cannot index " + (present ? describe(node) : std::string("a missing key")) + ", it is not a list");
    if (part.index >= node.size())
      throw PathError(source, here,
                      shown + ": list index out of range (the list has " + count_of(node.size(), "item") + ")");
    YAML::Node out(YAML::NodeType::Sequence);
    std::size_t j = 0;
    for (auto it = node.begin(); it != node.end(); ++it, ++j)
      out.push_back(j == part.index ? set_path(*it, true, ov, i + 1, here, source) : YAML::Node(*it));
    return out;
  }
  const std::string here = join_key(done, part.key);
  if (present && !node.IsNull() && !node.IsMap())
    throw PathError(source, done.empty() ? here : done,
                    shown + ": cannot set key '" + part.key + "' inside " + describe_kind(node) + ", it is not a map");
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
bool paths_related(const std::string& a, const std::string& b) { return path_within(a, b) || path_within(b, a); }

}  // namespace

bool path_within(const std::string& inner, const std::string& outer) {
  if (inner.empty() || outer.empty() || inner.compare(0, outer.size(), outer) != 0) return false;
  return inner.size() == outer.size() || inner[outer.size()] == '.' || inner[outer.size()] == '[';
}

// Not YAML::LoadAll: in yaml-cpp 0.7 it never returns for some malformed
// input (e.g. "!x\n,"), appending empty documents until memory runs out
// (jbeder/yaml-cpp#1040, fixed upstream by PR #1319). Instead the parser is
// asked for at most two documents, counting their nodes (a tree is never
// built for more than kMaxDocumentNodes), then YAML::Load builds the first.
YAML::Node load_document(const std::string& text, const std::string& source, const std::string& key_path,
                         const std::string& prefix, const DocumentKind& doc, bool allow_empty) {
  const auto error = [&](const std::string& reason) { return PathError(source, key_path, prefix + reason); };
  try {
    std::istringstream stream(text);
    YAML::Parser parser(stream);
    DocumentStarts starts;
    if (parser.HandleNextDocument(starts) && parser.HandleNextDocument(starts) && starts.starts.size() >= 2) {
      const YAML::Mark& second = starts.starts[1];
      const bool explicit_start = second.pos >= 0 && static_cast<std::size_t>(second.pos) < text.size() &&
                                  text.compare(static_cast<std::size_t>(second.pos), 3, "---") == 0;
      if (explicit_start)
        throw error("found a second YAML document at " + at_mark(second) + "; a " + doc.kind +
                    " is exactly one document");
      throw error("YAML syntax error at " + at_mark(second) + ": unexpected content after the document");
    }
    const YAML::Node root = YAML::Load(text);
    if (!root.IsDefined() || root.IsNull()) {
      if (allow_empty) return YAML::Node();
      throw error("empty document: " + doc.empty_hint);
    }
    return root;
  } catch (const TooManyNodes&) {
    throw error("more than " + std::to_string(kMaxDocumentNodes) + " YAML nodes (scalars, lists and maps); a " +
                doc.kind + " is far smaller, and the limit bounds the time and memory loading may take");
  } catch (const YAML::DeepRecursion& e) {
    throw error("YAML nesting too deep (the limit is " + std::to_string(e.depth()) + " levels)");
  } catch (const YAML::Exception& e) {
    throw error(syntax_error(e));
  }
}

Override parse_override(const std::string& text, const std::string& source, const DocumentKind& doc) {
  const std::string shown = "the override " + printable_override(text);
  const auto eq = text.find('=');
  if (eq == std::string::npos)
    throw PathError(source, "", shown + " is malformed: expected key.path=value (no '=' found)");
  Override ov;
  ov.text = text;
  const std::string key = trim(std::string_view(text).substr(0, eq));
  const auto bad_path = [&](const std::string& why) {
    return PathError(source, "", shown + " is malformed: bad key path " + printable(key) + ": " + why);
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
      Override::Part p;
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
      Override::Part p;
      p.key = key.substr(i, j - i);
      ov.parts.push_back(p);
      i = j;
    }
  }
  for (const Override::Part& p : ov.parts)
    ov.path = p.is_index ? join_index(ov.path, p.index) : join_key(ov.path, p.key);
  ov.value = load_document(text.substr(eq + 1), source, ov.path, shown + ": the value is not valid YAML: ", doc, true);
  return ov;
}

YAML::Node apply_override(const YAML::Node& root, const Override& ov, const std::string& source) {
  return set_path(root, true, ov, 0, "", source);
}

Document load_with_overrides(const std::string& text, const std::string& source,
                             const std::vector<std::string>& overrides, const DocumentKind& doc) {
  Document out;
  out.root = load_document(text, source, "", "", doc, false);
  out.overrides.reserve(overrides.size());
  for (const std::string& t : overrides) {
    out.overrides.push_back(parse_override(t, source, doc));
    out.root = apply_override(out.root, out.overrides.back(), source);
  }
  return out;
}

std::string blame_override(const std::vector<Override>& overrides, const std::string& key_path,
                           const std::string& reason) {
  for (auto it = overrides.rbegin(); it != overrides.rend(); ++it)
    if (paths_related(it->path, key_path))
      return reason + " (set by the override " + printable_override(it->text) + ")";
  return reason;
}

std::string read_text_file(const std::string& path, std::uintmax_t max_bytes, const std::string& what) {
  namespace fs = std::filesystem;
  const std::string cannot = "cannot read " + what + ": ";
  std::error_code ec;
  const fs::file_status st = fs::status(path, ec);
  if (st.type() == fs::file_type::not_found) throw PathError(path, "", cannot + "no such file");
  if (ec) throw PathError(path, "", cannot + ec.message());
  if (fs::is_directory(st)) throw PathError(path, "", cannot + "it is a directory");
  if (!fs::is_regular_file(st)) throw PathError(path, "", cannot + "not a regular file");
  const std::uintmax_t size = fs::file_size(path, ec);
  if (!ec && size > max_bytes)
    throw PathError(
        path, "",
        cannot + std::to_string(size) + " bytes is too large (the limit is " + std::to_string(max_bytes) + " bytes)");
  std::ifstream in(path, std::ios::binary);
  if (!in) throw PathError(path, "", cannot + std::strerror(errno));
  std::string text;
  char buf[65536];
  while (in.read(buf, sizeof buf) || in.gcount() > 0) {
    text.append(buf, static_cast<std::size_t>(in.gcount()));
    if (text.size() > max_bytes)
      throw PathError(path, "", cannot + "too large (the limit is " + std::to_string(max_bytes) + " bytes)");
  }
  if (in.bad()) throw PathError(path, "", cannot + "read error");
  return text;
}

}  // namespace tissue::yaml_util
