// The loaders' shared machinery (daemon/scene/yaml_util), function by
// function. The scene and daemon-config suites check what a user sees through
// the loaders; these check each function's own promise, exact messages and
// edge cases the loaders do not reach.
#include "scene/yaml_util.hpp"

#include <gtest/gtest.h>

#include <sys/stat.h>

#include <array>
#include <climits>
#include <cmath>
#include <functional>
#include <limits>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "support/process_support.hpp"

namespace tissue::yaml_util {
namespace {

using tissue::testing::TempDir;
using tissue::testing::write_text;

constexpr double kInf = std::numeric_limits<double>::infinity();
constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

const DocumentKind kKind{"thing", "a thing needs a section"};

// `fn` throws a PathError with exactly this source, key path and reason.
void expect_path_error(const std::function<void()>& fn, const std::string& source, const std::string& key_path,
                       const std::string& reason) {
  try {
    fn();
    ADD_FAILURE() << "no error; wanted " << key_path << ": " << reason;
  } catch (const PathError& e) {
    EXPECT_EQ(e.source(), source) << e.what();
    EXPECT_EQ(e.key_path(), key_path) << e.what();
    EXPECT_EQ(e.reason(), reason) << e.what();
  }
}

// `fn` throws a PathError naming `source` and `key_path` whose reason
// contains `part`; returns the reason.
std::string expect_reason_has(const std::function<void()>& fn, const std::string& source, const std::string& key_path,
                              const std::string& part) {
  try {
    fn();
    ADD_FAILURE() << "no error; wanted " << key_path << ": ..." << part << "...";
  } catch (const PathError& e) {
    EXPECT_EQ(e.source(), source) << e.what();
    EXPECT_EQ(e.key_path(), key_path) << e.what();
    EXPECT_NE(e.reason().find(part), std::string::npos) << e.what();
    return e.reason();
  }
  return {};
}

// ------------------------------------------------------------------ errors

// A loader's own error type, as SceneError and ConfigError are.
class TestError : public DocumentError {
 public:
  TestError(const std::string& source, const std::string& key_path, const std::string& reason)
      : DocumentError(source, key_path, reason, "<test>") {}
};

TEST(YamlUtil, ErrorTextIsSourceKeyPathReasonAndThePartsStayReadable) {
  const PathError full("scenes/a.yaml", "material.E", "must be > 0");
  EXPECT_STREQ(full.what(), "scenes/a.yaml: material.E: must be > 0");
  EXPECT_EQ(full.source(), "scenes/a.yaml");
  EXPECT_EQ(full.key_path(), "material.E");
  EXPECT_EQ(full.reason(), "must be > 0");
  // No key path: no empty ": :" part.
  EXPECT_STREQ(PathError("a.yaml", "", "no such file").what(), "a.yaml: no such file");
  // No source: the type's stand-in name, but source() stays empty.
  const PathError unnamed("", "k", "bad");
  EXPECT_STREQ(unnamed.what(), "<yaml>: k: bad");
  EXPECT_EQ(unnamed.source(), "");
  EXPECT_STREQ(TestError("", "", "bad").what(), "<test>: bad");
  // A copy carries the same parts.
  const PathError copy = full;
  EXPECT_EQ(copy.key_path(), "material.E");
  EXPECT_STREQ(copy.what(), full.what());
}

// -------------------------------------------------------------- formatting

TEST(YamlUtil, FmtNumIsShortestRoundTripAndSpellsNonFinites) {
  EXPECT_EQ(fmt_num(0.1), "0.1");
  EXPECT_EQ(fmt_num(5e4), "50000");
  EXPECT_EQ(fmt_num(-5), "-5");
  EXPECT_EQ(fmt_num(1e300), "1e+300");
  EXPECT_EQ(fmt_num(-0.0), "-0");
  EXPECT_EQ(fmt_num(kNaN), "nan");
  EXPECT_EQ(fmt_num(kInf), "inf");
  EXPECT_EQ(fmt_num(-kInf), "-inf");
  const double third = 1.0 / 3.0;
  EXPECT_EQ(std::stod(fmt_num(third)), third);
}

TEST(YamlUtil, PrintableEscapesControlBytesAndStopsAfterFortyCharacters) {
  EXPECT_EQ(printable_bare("plain text ~"), "plain text ~");
  EXPECT_EQ(printable_bare(std::string("a\tb\nc\x7f\xff", 7)), "a\\x09b\\x0Ac\\x7F\\xFF");
  EXPECT_EQ(printable_bare(std::string("\0z", 2)), "\\x00z");
  const std::string forty(40, 'x');
  EXPECT_EQ(printable_bare(forty), forty);
  EXPECT_EQ(printable_bare(forty + "y"), forty + "...");
  // An override is shown with its key whole (keys reach 45 characters:
  // 'adaptivity.simplify_min_age_steps=...' was cut inside the key) and its
  // value cut at 40, in quotes.
  EXPECT_EQ(printable_override("material.youngs_modulus_Pa=-1000000000000000"),
            "'material.youngs_modulus_Pa=-1000000000000000'");
  EXPECT_EQ(printable_override("a=" + forty + "y"), "'a=" + forty + "...'");
  EXPECT_EQ(printable_override("no equals sign"), "'no equals sign'");
  EXPECT_EQ(printable_override(std::string(300, 'k') + "=1"), "'" + std::string(120, 'k') + "...=1'");
  EXPECT_EQ(printable_bare(std::string(1000, 'q')).size(), 43u);
  EXPECT_EQ(printable("it's"), "'it's'");
  EXPECT_EQ(printable(""), "''");
}

TEST(YamlUtil, KeyPathsListsAndCountsAreJoinedForMessages) {
  EXPECT_EQ(join_key("", "object"), "object");
  EXPECT_EQ(join_key("object", "cubes"), "object.cubes");
  EXPECT_EQ(join_index("loads", 0), "loads[0]");
  EXPECT_EQ(join_key(join_index("loads", 12), "name"), "loads[12].name");
  const std::array<std::string_view, 3> keys{"a", "bb", "c"};
  EXPECT_EQ(join_list(keys), "a, bb, c");
  EXPECT_EQ(join_list(KeyList()), "");
  EXPECT_EQ(count_of(0, "item"), "0 items");
  EXPECT_EQ(count_of(1, "item"), "1 item");
  EXPECT_EQ(count_of(2, "item"), "2 items");
}

TEST(YamlUtil, SuggestFindsCloseTyposAndMissingUnitSuffixesOnly) {
  const std::array<std::string_view, 4> allowed{"youngs_modulus_Pa", "density_kg_per_m3", "damping", "dt_s"};
  EXPECT_EQ(suggest("youngs_modulus", allowed), "youngs_modulus_Pa");  // a missing unit suffix
  EXPECT_EQ(suggest("dampnig", allowed), "damping");                   // a swap is distance 2
  EXPECT_EQ(suggest("density_kg_per_m", allowed), "density_kg_per_m3");
  EXPECT_EQ(suggest("dt", allowed), "dt_s");
  EXPECT_FALSE(suggest("colour", allowed).has_value());  // nothing close
  EXPECT_FALSE(suggest("", allowed).has_value());
  EXPECT_FALSE(suggest(std::string(65, 'd'), allowed).has_value());
  // Short keys allow 2 edits, not 3.
  const std::array<std::string_view, 1> one{"abcd"};
  EXPECT_EQ(suggest("abxy", one), "abcd");
  EXPECT_FALSE(suggest("axyz", one).has_value());
  // Longer keys allow a third of their length: 4 edits in 12 characters.
  const std::array<std::string_view, 1> longer{"abcdefghijkl"};
  EXPECT_EQ(suggest("abcdefghWXYZ", longer), "abcdefghijkl");
  EXPECT_FALSE(suggest("abcdefgVWXYZ", longer).has_value());
  // The closest of several wins.
  const std::array<std::string_view, 2> two{"max_depth", "min_depth"};
  EXPECT_EQ(suggest("mix_depth", two), "max_depth");
  EXPECT_EQ(suggest("mon_depth", two), "min_depth");
}

// ----------------------------------------------------------------- scalars

TEST(YamlUtil, QuotedScalarsAndNodeDescriptions) {
  EXPECT_FALSE(is_quoted(YAML::Load("5")));
  EXPECT_TRUE(is_quoted(YAML::Load("'5'")));
  EXPECT_TRUE(is_quoted(YAML::Load("\"5\"")));
  EXPECT_TRUE(is_quoted(YAML::Load("!!str 5")));
  EXPECT_EQ(describe(YAML::Load("fast")), "'fast'");
  EXPECT_EQ(describe(YAML::Load("'5'")), "the quoted string '5'");
  EXPECT_EQ(describe(YAML::Load("~")), "null");
  EXPECT_EQ(describe(YAML::Load("[1]")), "a list");
  EXPECT_EQ(describe(YAML::Load("{a: 1}")), "a map");
  EXPECT_EQ(describe(YAML::Load("{a: 1}")["missing"]), "nothing");
  EXPECT_EQ(describe(YAML::Load("\"tab\\there\"")), "the quoted string 'tab\\x09here'");
  EXPECT_TRUE(is_digit('0') && is_digit('9'));
  EXPECT_FALSE(is_digit('a') || is_digit('/') || is_digit(':'));
}

double float_of(std::string_view s) {
  double v = -12345.0;
  EXPECT_EQ(parse_float(s, &v), NumberParse::kOk) << s;
  return v;
}

TEST(YamlUtil, ParseFloatTakesYamlCoreDecimalsAndInfNan) {
  EXPECT_EQ(float_of("0"), 0.0);
  EXPECT_EQ(float_of("-2.5"), -2.5);
  EXPECT_EQ(float_of("+2."), 2.0);
  EXPECT_EQ(float_of(".5"), 0.5);
  EXPECT_EQ(float_of("1.5E3"), 1500.0);
  EXPECT_EQ(float_of("-9.81e-1"), -0.981);
  EXPECT_EQ(float_of("2e+2"), 200.0);
  EXPECT_TRUE(std::signbit(float_of("-0")));
  for (const char* s : {".inf", ".Inf", ".INF", "+.inf"}) EXPECT_EQ(float_of(s), kInf) << s;
  for (const char* s : {"-.inf", "-.Inf", "-.INF"}) EXPECT_EQ(float_of(s), -kInf) << s;
  for (const char* s : {".nan", ".NaN", ".NAN"}) EXPECT_TRUE(std::isnan(float_of(s))) << s;
  // Not numbers: other spellings, hex, units, spaces, stray signs, a bare
  // exponent. The output is left alone.
  for (const char* s : {"", ".", "+", "-", "e5", "1e", "1e+", "1.2.3", "0x1A", "1_000", " 1", "1 ", "5ms", "inf", "nan",
                        "-.nan", "+-1", "1,5", ".inf0"}) {
    double v = 7.0;
    EXPECT_EQ(parse_float(s, &v), NumberParse::kNotANumber) << "'" << s << "'";
    EXPECT_EQ(v, 7.0) << s;
  }
  double v = 7.0;
  EXPECT_EQ(parse_float("1e400", &v), NumberParse::kOutOfRange);
  EXPECT_EQ(parse_float("-1e400", &v), NumberParse::kOutOfRange);
  EXPECT_EQ(v, 7.0);
}

TEST(YamlUtil, ParseIntTakesDecimalIntegersThatFitAnInt) {
  int v = -1;
  EXPECT_EQ(parse_int("42", &v), NumberParse::kOk);
  EXPECT_EQ(v, 42);
  EXPECT_EQ(parse_int("+7", &v), NumberParse::kOk);
  EXPECT_EQ(v, 7);
  EXPECT_EQ(parse_int("-0", &v), NumberParse::kOk);
  EXPECT_EQ(v, 0);
  EXPECT_EQ(parse_int("007", &v), NumberParse::kOk);
  EXPECT_EQ(v, 7);
  EXPECT_EQ(parse_int("2147483647", &v), NumberParse::kOk);
  EXPECT_EQ(v, INT_MAX);
  EXPECT_EQ(parse_int("-2147483648", &v), NumberParse::kOk);
  EXPECT_EQ(v, INT_MIN);
  v = 3;
  for (const char* s : {"2147483648", "-2147483649", "99999999999999999999", "-99999999999999999999"})
    EXPECT_EQ(parse_int(s, &v), NumberParse::kOutOfRange) << s;
  for (const char* s : {"", "+", "-", "+-5", "-+5", "1.0", "1e3", "0x10", " 1", "1 ", "--1", "12a"})
    EXPECT_EQ(parse_int(s, &v), NumberParse::kNotANumber) << "'" << s << "'";
  EXPECT_EQ(v, 3);  // untouched by every failure
}

// ---------------------------------------------------------- typed reading

// A key's node in a one-line YAML map, for reading it.
YAML::Node value_of(const std::string& yaml) { return YAML::Load("v: " + yaml)["v"]; }

TEST(YamlUtil, ReadDoubleAcceptsNumbersAndNamesTheKeyOtherwise) {
  const Reader r("f.yaml");
  double d = 0.0;
  r.read(value_of("3"), "a.b", d);
  EXPECT_EQ(d, 3.0);
  r.read(value_of("-.inf"), "a.b", d);
  EXPECT_EQ(d, -kInf);
  r.read(value_of(".nan"), "a.b", d);
  EXPECT_TRUE(std::isnan(d));  // read, not judged: finiteness is ValueChecks' business
  const auto fails = [&](const std::string& yaml, const std::string& reason) {
    expect_path_error([&] { r.read(value_of(yaml), "a.b", d); }, "f.yaml", "a.b", reason);
  };
  fails("fast", "expected a number, got 'fast'");
  fails("'5'", "expected a number, got the quoted string '5'");
  fails("!!str 5", "expected a number, got the quoted string '5'");
  fails("[1]", "expected a number, got a list");
  fails("{x: 1}", "expected a number, got a map");
  fails("~", "expected a number, got null");
  fails("1e999", "number out of range: '1e999'");
}

TEST(YamlUtil, ReadIntRejectsRealsQuotedAndOutOfRange) {
  const Reader r("f.yaml");
  int i = 0;
  r.read(value_of("-12"), "n", i);
  EXPECT_EQ(i, -12);
  expect_path_error([&] { r.read(value_of("2.5"), "n", i); }, "f.yaml", "n", "expected an integer, got '2.5'");
  expect_path_error([&] { r.read(value_of("\"4\""), "n", i); }, "f.yaml", "n",
                    "expected an integer, got the quoted string '4'");
  expect_path_error([&] { r.read(value_of("3000000000"), "n", i); }, "f.yaml", "n",
                    "integer out of range: '3000000000'");
  expect_path_error([&] { r.read(value_of("[1, 2]"), "n", i); }, "f.yaml", "n", "expected an integer, got a list");
  EXPECT_EQ(i, -12);
}

TEST(YamlUtil, ReadSizeTakesNonNegativeIntegersOnly) {
  const Reader r("f.yaml");
  std::size_t n = 0;
  r.read(value_of("65536"), "control.max", n);
  EXPECT_EQ(n, 65536u);
  r.read(value_of("+3"), "control.max", n);
  EXPECT_EQ(n, 3u);
  r.read(value_of("18446744073709551615"), "control.max", n);
  EXPECT_EQ(n, std::numeric_limits<std::size_t>::max());
  const auto fails = [&](const std::string& yaml, const std::string& reason) {
    expect_path_error([&] { r.read(value_of(yaml), "control.max", n); }, "f.yaml", "control.max", reason);
  };
  fails("-1", "must be >= 0 (got -1)");
  fails("18446744073709551616", "integer out of range: '18446744073709551616'");
  fails("1.5", "expected a non-negative integer, got '1.5'");
  fails("1e3", "expected a non-negative integer, got '1e3'");
  fails("-a", "expected a non-negative integer, got '-a'");
  expect_path_error([&] { r.read(YAML::Node(std::string("-")), "control.max", n); }, "f.yaml", "control.max",
                    "expected a non-negative integer, got '-'");
  fails("+", "expected a non-negative integer, got '+'");
  fails("'7'", "expected a non-negative integer, got the quoted string '7'");
  fails("{a: 1}", "expected a non-negative integer, got a map");
}

TEST(YamlUtil, ReadBoolTakesTheYamlCoreSpellingsOnly) {
  const Reader r("f.yaml");
  for (const char* s : {"true", "True", "TRUE"}) {
    bool b = false;
    r.read(value_of(s), "on", b);
    EXPECT_TRUE(b) << s;
  }
  for (const char* s : {"false", "False", "FALSE"}) {
    bool b = true;
    r.read(value_of(s), "on", b);
    EXPECT_FALSE(b) << s;
  }
  bool b = true;
  for (const auto& [yaml, shown] :
       std::vector<std::pair<std::string, std::string>>{{"yes", "'yes'"},
                                                        {"1", "'1'"},
                                                        {"tRUE", "'tRUE'"},
                                                        {"'true'", "the quoted string 'true'"},
                                                        {"[]", "a list"}})
    expect_path_error([&] { r.read(value_of(yaml), "on", b); }, "f.yaml", "on",
                      "expected a boolean (true or false), got " + shown);
  EXPECT_TRUE(b);
}

TEST(YamlUtil, ReadStringTakesAnyScalarButNotNullOrCollections) {
  const Reader r("f.yaml");
  std::string s;
  r.read(value_of("'5'"), "name", s);
  EXPECT_EQ(s, "5");
  r.read(value_of("12"), "name", s);  // a plain number is text here
  EXPECT_EQ(s, "12");
  r.read(value_of("\"two words\""), "name", s);
  EXPECT_EQ(s, "two words");
  expect_path_error([&] { r.read(value_of("[a]"), "name", s); }, "f.yaml", "name", "expected a string, got a list");
  expect_path_error([&] { r.read(value_of("~"), "name", s); }, "f.yaml", "name", "expected a string, got null");
  EXPECT_EQ(s, "two words");
}

TEST(YamlUtil, ReadTripleCountsItemsAndNamesTheBadOne) {
  const Reader r("f.yaml");
  std::array<double, 3> v{};
  r.read(value_of("[1, -2.5, .inf]"), "g", v);
  EXPECT_EQ(v, (std::array<double, 3>{1, -2.5, kInf}));
  std::array<int, 3> c{};
  r.read(value_of("[4, 5, 6]"), "object.cubes", c);
  EXPECT_EQ(c, (std::array<int, 3>{4, 5, 6}));
  expect_path_error([&] { r.read(value_of("[1, 2]"), "g", v); }, "f.yaml", "g",
                    "expected a list of 3 numbers, got 2 items");
  expect_path_error([&] { r.read(value_of("[1]"), "g", v); }, "f.yaml", "g",
                    "expected a list of 3 numbers, got 1 item");
  expect_path_error([&] { r.read(value_of("[1, 2, 3, 4]"), "object.cubes", c); }, "f.yaml", "object.cubes",
                    "expected a list of 3 integers, got 4 items");
  expect_path_error([&] { r.read(value_of("5"), "object.cubes", c); }, "f.yaml", "object.cubes",
                    "expected a list of 3 integers, got '5'");
  expect_path_error([&] { r.read(value_of("[1, x, 3]"), "g", v); }, "f.yaml", "g[1]", "expected a number, got 'x'");
  expect_path_error([&] { r.read(value_of("[1, 2, 3.5]"), "object.cubes", c); }, "f.yaml", "object.cubes[2]",
                    "expected an integer, got '3.5'");
}

enum class Colour { kRed, kGreen };
constexpr std::array<std::pair<std::string_view, Colour>, 2> kColours{
    {{"red", Colour::kRed}, {"green", Colour::kGreen}}};

TEST(YamlUtil, ChoicesMatchExactlyAndListTheAllowedValues) {
  const Reader r("f.yaml");
  const Choices<Colour> choices(kColours);
  EXPECT_EQ(choice_names(choices), "red, green");
  Colour c = Colour::kRed;
  r.read_choice(value_of("green"), "paint", choices, c);
  EXPECT_EQ(c, Colour::kGreen);
  expect_path_error([&] { r.read_choice(value_of("Red"), "paint", choices, c); }, "f.yaml", "paint",
                    "unknown value 'Red'; allowed values: red, green");
  expect_path_error([&] { r.read_choice(value_of("[red]"), "paint", choices, c); }, "f.yaml", "paint",
                    "expected one of red, green, got a list");
  EXPECT_EQ(c, Colour::kGreen);
  // opt_choice: absent leaves the value, present reads it under the key.
  const FieldMap f = r.fields(YAML::Load("paint: red"), "car", {"paint", "wheels"});
  Colour keep = Colour::kGreen;
  r.opt_choice(f, "wheels", "car", choices, keep);
  EXPECT_EQ(keep, Colour::kGreen);
  r.opt_choice(f, "paint", "car", choices, keep);
  EXPECT_EQ(keep, Colour::kRed);
  const FieldMap bad = r.fields(YAML::Load("paint: blue"), "car", {"paint"});
  expect_reason_has([&] { r.opt_choice(bad, "paint", "car", choices, keep); }, "f.yaml", "car.paint",
                    "unknown value 'blue'");
}

TEST(YamlUtil, FieldsChecksKeysAgainstTheAllowedOnes) {
  const Reader r("f.yaml");
  const FieldMap f = r.fields(YAML::Load("{b: 2, a: 1}"), "sec", {"a", "b", "c"});
  ASSERT_EQ(f.size(), 2u);
  EXPECT_EQ(f.at("a").Scalar(), "1");
  EXPECT_EQ(f.at("b").Scalar(), "2");
  EXPECT_TRUE(r.fields(YAML::Load("{}"), "sec", {"a"}).empty());

  expect_path_error(
      [&] {
        r.fields(YAML::Load("{a: 1, colour: red}"), "sec", {"a", "b"});
      },
      "f.yaml", "sec.colour", "unknown key 'colour'; allowed keys: a, b");
  expect_path_error(
      [&] {
        r.fields(YAML::Load("{rate_Hz: 1}"), "haptics", {"rate_hz", "crossfade_s"});
      },
      "f.yaml", "haptics.rate_Hz",
      "unknown key 'rate_Hz' (did you mean 'rate_hz'?); allowed keys: rate_hz, crossfade_s");
  // At the top level the key path is the key alone.
  expect_path_error([&] { r.fields(YAML::Load("{x: 1}"), "", {"width"}); }, "f.yaml", "x",
                    "unknown key 'x'; allowed keys: width");
  // A key that is no plain name (a tab, a ':', a '$': a line of a file that
  // is not a scene) is not echoed, in the path or the reason.
  for (const char* key : {"\"a\\tb\"", "\"root:x:0:0\"", "\"h$6$salt\""})
    expect_path_error([&] { r.fields(YAML::Load(std::string("{") + key + ": 1}"), "sec", {"width"}); }, "f.yaml",
                      "sec.<key not shown>",
                      "unknown key that is not a plain name (letters, digits, '_', '-'; up to 64), not shown; allowed "
                      "keys: width");
  // A merge key is named as one (yaml-cpp does not merge: it is a key "<<").
  expect_path_error([&] { r.fields(YAML::Load("{base: &m {a: 1}, sec: {<<: *m}}")["sec"], "sec", {"a"}); }, "f.yaml",
                    "sec.<<",
                    "YAML merge keys (<<: *anchor) are not supported; write the keys out (anchors and aliases of "
                    "whole values are)");
  expect_path_error(
      [&] {
        r.fields(YAML::Load("{a: 1, b: 2, a: 3}"), "sec", {"a", "b"});
      },
      "f.yaml", "sec.a", "duplicate key");
  expect_path_error([&] { r.fields(YAML::Load("{[a]: 1}"), "sec", {"a"}); }, "f.yaml", "sec",
                    "map keys must be plain names, got a list");
  expect_path_error(
      [&] {
        r.fields(YAML::Load("[a, b]"), "sec", {"a", "b"});
      },
      "f.yaml", "sec", "expected a map with keys a, b, got a list");
  expect_path_error([&] { r.fields(YAML::Load("a"), "sec", {"a"}); }, "f.yaml", "sec",
                    "expected a map with keys a, got 'a'");
}

TEST(YamlUtil, RequireAndOptReadUnderTheJoinedKeyPath) {
  const Reader r("f.yaml");
  const FieldMap f = r.fields(YAML::Load("{dt_s: 0.5, steps: x}"), "integrator", {"dt_s", "steps", "kind"});
  EXPECT_EQ(r.require(f, "dt_s", "integrator").Scalar(), "0.5");
  expect_path_error([&] { r.require(f, "kind", "integrator"); }, "f.yaml", "integrator.kind", "missing required key");
  double dt = 9.0;
  r.opt(f, "dt_s", "integrator", dt);
  EXPECT_EQ(dt, 0.5);
  std::string kind = "default";
  r.opt(f, "kind", "integrator", kind);  // absent: unchanged
  EXPECT_EQ(kind, "default");
  int steps = 4;
  expect_path_error([&] { r.opt(f, "steps", "integrator", steps); }, "f.yaml", "integrator.steps",
                    "expected an integer, got 'x'");
  EXPECT_EQ(steps, 4);
  expect_path_error([&] { r.fail("some.key", "why"); }, "f.yaml", "some.key", "why");
  EXPECT_EQ(r.source(), "f.yaml");
}

TEST(YamlUtil, ForEachVisitsItemsWithIndexedPaths) {
  const Reader r("f.yaml");
  std::vector<std::string> seen;
  r.for_each(YAML::Load("[a, b, c]"), "probes",
             [&](const YAML::Node& n, const std::string& path) { seen.push_back(path + "=" + n.Scalar()); });
  EXPECT_EQ(seen, (std::vector<std::string>{"probes[0]=a", "probes[1]=b", "probes[2]=c"}));
  int calls = 0;
  r.for_each(YAML::Load("[]"), "probes", [&](const YAML::Node&, const std::string&) { ++calls; });
  EXPECT_EQ(calls, 0);
  expect_path_error([&] { r.for_each(YAML::Load("{a: 1}"), "probes", [](const YAML::Node&, const std::string&) {}); },
                    "f.yaml", "probes", "expected a list, got a map (write [] for none)");
  expect_path_error([&] { r.for_each(YAML::Load("~"), "probes", [](const YAML::Node&, const std::string&) {}); },
                    "f.yaml", "probes", "expected a list, got null (write [] for none)");
}

// A validator in the CRTP shape the loaders use.
class Checks : private ValueChecks<Checks> {
  friend class ValueChecks<Checks>;

 public:
  using ValueChecks<Checks>::finite;
  using ValueChecks<Checks>::positive;
  using ValueChecks<Checks>::non_negative;
  [[noreturn]] void fail(const std::string& path, const std::string& reason) const {
    throw TestError("checked.yaml", path, reason);
  }
};

// `fn` throws TestError at `key_path` with exactly `reason`.
void expect_check_error(const std::function<void()>& fn, const std::string& key_path, const std::string& reason) {
  try {
    fn();
    ADD_FAILURE() << "no error; wanted " << key_path << ": " << reason;
  } catch (const TestError& e) {
    EXPECT_EQ(e.source(), "checked.yaml");
    EXPECT_EQ(e.key_path(), key_path) << e.what();
    EXPECT_EQ(e.reason(), reason) << e.what();
  }
}

TEST(YamlUtil, ValueChecksRejectNonFiniteAndOutOfRangeWithTheValue) {
  const Checks c;
  EXPECT_NO_THROW(c.finite(-1e300, "x"));
  EXPECT_NO_THROW(c.positive(1e-300, "x"));
  EXPECT_NO_THROW(c.non_negative(0.0, "x"));
  EXPECT_NO_THROW(c.non_negative(-0.0, "x"));
  EXPECT_NO_THROW(c.finite(std::array<double, 3>{0, 1, -2}, "g"));
  expect_check_error([&] { c.finite(kNaN, "m.E"); }, "m.E", "must be a finite number (got nan)");
  expect_check_error([&] { c.finite(-kInf, "m.E"); }, "m.E", "must be a finite number (got -inf)");
  expect_check_error(
      [&] {
        c.finite(std::array<double, 3>{0, 1, kInf}, "g");
      },
      "g[2]", "must be a finite number (got inf)");
  expect_check_error(
      [&] {
        c.finite(std::array<double, 3>{kNaN, 1, 2}, "g");
      },
      "g[0]", "must be a finite number (got nan)");
  expect_check_error([&] { c.positive(0.0, "m.E"); }, "m.E", "must be > 0 (got 0)");
  expect_check_error([&] { c.positive(-2.5, "m.E"); }, "m.E", "must be > 0 (got -2.5)");
  expect_check_error([&] { c.positive(kNaN, "m.E"); }, "m.E", "must be a finite number (got nan)");
  expect_check_error([&] { c.positive(kInf, "m.E"); }, "m.E", "must be a finite number (got inf)");
  expect_check_error([&] { c.non_negative(-1e-9, "r"); }, "r", "must be >= 0 (got -1e-09)");
  expect_check_error([&] { c.non_negative(kNaN, "r"); }, "r", "must be a finite number (got nan)");
}

// ---------------------------------------------------------------- documents

TEST(YamlUtil, LoadDocumentTakesExactlyOneDocument) {
  const YAML::Node n = load_document("a: 1\nb: [2, 3]\n", "f.yaml", "", "", kKind, false);
  ASSERT_TRUE(n.IsMap());
  EXPECT_EQ(n["b"][1].Scalar(), "3");
  EXPECT_TRUE(load_document("---\na: 1\n...\n", "f.yaml", "", "", kKind, false).IsMap());
  const auto load = [](const std::string& text) {
    return [text] { load_document(text, "f.yaml", "", "", kKind, false); };
  };
  expect_path_error(load("a: 1\n---\nb: 2\n"), "f.yaml", "",
                    "found a second YAML document at line 2, column 1; a thing is exactly one document");
  expect_path_error(load("a: 1\n...\nb: 2\n"), "f.yaml", "",
                    "YAML syntax error at line 3, column 1: unexpected content after the document");
  expect_path_error(load(""), "f.yaml", "", "empty document: a thing needs a section");
  expect_path_error(load("~\n"), "f.yaml", "", "empty document: a thing needs a section");
  expect_reason_has(load("a: 1\nb: [2, 3\n"), "f.yaml", "", "YAML syntax error at line 3, column 1: ");
  expect_reason_has(load(std::string(20000, '[')), "f.yaml", "", "YAML nesting too deep (the limit is ");
}

// The node count is checked in the event pass, before yaml-cpp builds a tree:
// a megabyte of "0," is half a million nodes, seconds and gigabytes to build.
TEST(YamlUtil, LoadDocumentRefusesMoreThanAHundredThousandNodes) {
  const auto flow_list = [](std::size_t items) {
    std::string text = "[";
    for (std::size_t i = 0; i < items; ++i) text += i == 0 ? "0" : ",0";
    return text + "]";
  };
  // The list and its items: exactly the limit, then one more.
  EXPECT_EQ(load_document(flow_list(99'999), "f.yaml", "", "", kKind, false).size(), 99'999u);
  expect_path_error([&] { load_document(flow_list(100'000), "f.yaml", "k", "PRE: ", kKind, true); }, "f.yaml", "k",
                    "PRE: more than 100000 YAML nodes (scalars, lists and maps); a thing is far smaller, and the "
                    "limit bounds the time and memory loading may take");
  // Maps and aliases count too.
  std::string maps = "- &a {x: 1}\n";
  for (int i = 0; i < 33'333; ++i) maps += "- *a\n";
  EXPECT_NO_THROW(load_document(maps, "f.yaml", "", "", kKind, false));  // 1 + 3 + 33333 nodes
  for (int i = 0; i < 70'000; ++i) maps += "- *a\n";
  expect_reason_has([&] { load_document(maps, "f.yaml", "", "", kKind, false); }, "f.yaml", "",
                    "more than 100000 YAML nodes");
}

TEST(YamlUtil, LoadDocumentPrefixKeyPathAndAllowEmpty) {
  // Empty is a value when allowed (an override's "key=").
  const YAML::Node empty = load_document("", "f.yaml", "k", "", kKind, true);
  EXPECT_TRUE(empty.IsNull());
  EXPECT_TRUE(load_document("# only a comment\n", "f.yaml", "k", "", kKind, true).IsNull());
  // The prefix starts every reason and the key path is the caller's.
  expect_path_error([] { load_document("a: 1\n---\nb: 2\n", "f.yaml", "x.y", "PRE: ", kKind, true); }, "f.yaml", "x.y",
                    "PRE: found a second YAML document at line 2, column 1; a thing is exactly one document");
  expect_path_error([] { load_document("", "f.yaml", "x.y", "PRE: ", kKind, false); }, "f.yaml", "x.y",
                    "PRE: empty document: a thing needs a section");
  expect_reason_has([] { load_document("[1", "f.yaml", "x.y", "PRE: ", kKind, true); }, "f.yaml", "x.y",
                    "PRE: YAML syntax error at line ");
}

TEST(YamlUtil, ParseOverrideSplitsTheKeyPathAndParsesTheValue) {
  const Override ov = parse_override(" loads[2].region[10].max_m = [1, 2, 3] ", "f.yaml", kKind);
  EXPECT_EQ(ov.text, " loads[2].region[10].max_m = [1, 2, 3] ");
  EXPECT_EQ(ov.path, "loads[2].region[10].max_m");
  ASSERT_EQ(ov.parts.size(), 5u);
  EXPECT_FALSE(ov.parts[0].is_index);
  EXPECT_EQ(ov.parts[0].key, "loads");
  EXPECT_TRUE(ov.parts[1].is_index);
  EXPECT_EQ(ov.parts[1].index, 2u);
  EXPECT_EQ(ov.parts[2].key, "region");
  EXPECT_TRUE(ov.parts[3].is_index);
  EXPECT_EQ(ov.parts[3].index, 10u);
  EXPECT_FALSE(ov.parts[4].is_index);
  EXPECT_EQ(ov.parts[4].key, "max_m");
  ASSERT_TRUE(ov.value.IsSequence());
  EXPECT_EQ(ov.value[2].Scalar(), "3");
  // Keys may hold letters, digits, '_' and '-'; only the first '=' splits.
  const Override eq = parse_override("a-b_C9=x=y", "f.yaml", kKind);
  EXPECT_EQ(eq.path, "a-b_C9");
  EXPECT_EQ(eq.value.Scalar(), "x=y");
  EXPECT_TRUE(parse_override("a=", "f.yaml", kKind).value.IsNull());
  EXPECT_TRUE(is_quoted(parse_override("a='5'", "f.yaml", kKind).value));
}

TEST(YamlUtil, MalformedOverridesSayWhatIsWrongWithThePath) {
  const auto bad = [](const std::string& text, const std::string& reason) {
    expect_path_error([&] { parse_override(text, "f.yaml", kKind); }, "f.yaml", "", reason);
  };
  bad("a.b", "the override 'a.b' is malformed: expected key.path=value (no '=' found)");
  bad(" =1", "the override ' =1' is malformed: bad key path '': it is empty");
  bad("[0]=1", "the override '[0]=1' is malformed: bad key path '[0]': it must start with a key");
  bad(".a=1", "the override '.a=1' is malformed: bad key path '.a': it must start with a key");
  bad("a[0=1", "the override 'a[0=1' is malformed: bad key path 'a[0': missing ']'");
  bad("a[]=1", "the override 'a[]=1' is malformed: bad key path 'a[]': a list index must be a non-negative integer");
  bad("a[-1]=1",
      "the override 'a[-1]=1' is malformed: bad key path 'a[-1]': a list index must be a non-negative integer");
  bad("a[99999999999999999999999]=1",
      "the override 'a[99999999999999999999999]=1' is malformed: bad key path 'a[99999999999999999999999]': list index "
      "out of range");
  bad("a[0]b=1", "the override 'a[0]b=1' is malformed: bad key path 'a[0]b': expected '.' or '[' after ']'");
  bad("a.$=1", "the override 'a.$=1' is malformed: bad key path 'a.$': expected a key name at position 3");
  bad("a b=1", "the override 'a b=1' is malformed: bad key path 'a b': expected a key name at position 2");
  bad("a.=1", "the override 'a.=1' is malformed: bad key path 'a.': expected a key name at position 3");
  // A value that is not YAML is named under the override's key path.
  expect_reason_has([] { parse_override("a.b=[1", "f.yaml", kKind); }, "f.yaml", "a.b",
                    "the override 'a.b=[1': the value is not valid YAML: YAML syntax error at line ");
  expect_reason_has([] { parse_override("a=1\n---\n2", "f.yaml", kKind); }, "f.yaml", "a",
                    "the override 'a=1\\x0A---\\x0A2': the value is not valid YAML: found a second YAML document");
}

std::string dump(const YAML::Node& n) {
  YAML::Emitter out;
  out << YAML::Flow << n;
  return out.c_str();
}

YAML::Node overridden(const std::string& text, const std::string& override_text) {
  return apply_override(YAML::Load(text), parse_override(override_text, "f.yaml", kKind), "f.yaml");
}

TEST(YamlUtil, ApplyOverrideReplacesCreatesAndLeavesTheRestAlone) {
  EXPECT_EQ(dump(overridden("{a: {b: 1, c: 2}, d: 3}", "a.b=5")), "{a: {b: 5, c: 2}, d: 3}");
  EXPECT_EQ(dump(overridden("{l: [1, [2, 3]], d: 3}", "l[1][0]=x")), "{l: [1, [x, 3]], d: 3}");
  // Missing maps on the path are created, a null one becomes a map.
  EXPECT_EQ(dump(overridden("{d: 3}", "x.y.z=1")), "{d: 3, x: {y: {z: 1}}}");
  EXPECT_EQ(dump(overridden("{n: ~}", "n.k=1")), "{n: {k: 1}}");
  // A whole subtree can be replaced.
  EXPECT_EQ(dump(overridden("{a: {b: 1}}", "a={q: [1]}")), "{a: {q: [1]}}");
  // The original tree is not modified: the result is a copy.
  const YAML::Node root = YAML::Load("{a: {b: 1}, l: [1, 2]}");
  const YAML::Node changed = apply_override(apply_override(root, parse_override("a.b=2", "f.yaml", kKind), "f.yaml"),
                                            parse_override("l[0]=9", "f.yaml", kKind), "f.yaml");
  EXPECT_EQ(dump(root), "{a: {b: 1}, l: [1, 2]}");
  EXPECT_EQ(dump(changed), "{a: {b: 2}, l: [9, 2]}");
}

TEST(YamlUtil, ApplyOverrideErrorsNameWhereThePathBreaks) {
  const auto fails = [](const std::string& text, const std::string& ov, const std::string& key_path,
                        const std::string& reason) {
    expect_path_error([&] { overridden(text, ov); }, "f.yaml", key_path, reason);
  };
  fails("{l: [1, 2]}", "l[5]=0", "l[5]", "the override 'l[5]=0': list index out of range (the list has 2 items)");
  fails("{l: [[1]]}", "l[0][1]=0", "l[0][1]",
        "the override 'l[0][1]=0': list index out of range (the list has 1 item)");
  fails("{m: {a: 1}}", "m[0]=0", "m", "the override 'm[0]=0': cannot index a map, it is not a list");
  fails("{m: {a: 1}}", "nope[0]=0", "nope", "the override 'nope[0]=0': cannot index a missing key, it is not a list");
  fails("{s: text}", "s.k=0", "s",
        "the override 's.k=0': cannot set key 'k' inside a line of text (contents not shown), it is not a map");
  fails("{l: [1]}", "l.k=0", "l", "the override 'l.k=0': cannot set key 'k' inside a list, it is not a map");
  fails("5", "a=1", "a",
        "the override 'a=1': cannot set key 'a' inside a line of text (contents not shown), it is not a map");
}

TEST(YamlUtil, LoadWithOverridesAppliesThemInOrder) {
  const Document d = load_with_overrides("a: 1\nb: {c: 2}\n", "f.yaml", {"a=2", "b.c=3", "a=4"}, kKind);
  EXPECT_EQ(dump(d.root), "{a: 4, b: {c: 3}}");
  ASSERT_EQ(d.overrides.size(), 3u);
  EXPECT_EQ(d.overrides[1].text, "b.c=3");
  EXPECT_EQ(d.overrides[2].path, "a");
  expect_reason_has(
      [] {
        load_with_overrides("a: 1\n", "f.yaml", {"a=2", "zz"}, kKind);
      },
      "f.yaml", "", "the override 'zz' is malformed");
  expect_path_error([] { load_with_overrides("", "f.yaml", {"a=2"}, kKind); }, "f.yaml", "",
                    "empty document: a thing needs a section");
}

TEST(YamlUtil, PathWithinMeansTheSameNodeOrOneInsideIt) {
  EXPECT_TRUE(path_within("a.b", "a.b"));
  EXPECT_TRUE(path_within("a.b.c", "a.b"));
  EXPECT_TRUE(path_within("a.b[2].c", "a.b"));
  EXPECT_FALSE(path_within("a.b", "a.b.c"));  // one direction only: the outer one contains
  EXPECT_FALSE(path_within("a.bc", "a.b"));   // a longer key, not a child
  EXPECT_FALSE(path_within("l[01]", "l[0]"));
  EXPECT_FALSE(path_within("", "a"));
  EXPECT_FALSE(path_within("a", ""));
}

TEST(YamlUtil, BlameOverrideNamesTheLatestRelatedOverride) {
  const Document d = load_with_overrides("l: [0]", "f.yaml", {"a.b=1", "l[0]=2", "a.b=3", "x=4"}, kKind);
  const auto& ovs = d.overrides;
  EXPECT_EQ(blame_override(ovs, "a.b", "bad"), "bad (set by the override 'a.b=3')");    // the later of two
  EXPECT_EQ(blame_override(ovs, "a.b.c", "bad"), "bad (set by the override 'a.b=3')");  // inside it
  EXPECT_EQ(blame_override(ovs, "a", "bad"), "bad (set by the override 'a.b=3')");      // contains it
  EXPECT_EQ(blame_override(ovs, "l[0].name", "bad"), "bad (set by the override 'l[0]=2')");
  EXPECT_EQ(blame_override(ovs, "l", "bad"), "bad (set by the override 'l[0]=2')");
  EXPECT_EQ(blame_override(ovs, "x", "bad"), "bad (set by the override 'x=4')");
  // Unrelated paths, including a mere common prefix, are not blamed.
  EXPECT_EQ(blame_override(ovs, "a.bc", "bad"), "bad");
  EXPECT_EQ(blame_override(ovs, "xy", "bad"), "bad");
  EXPECT_EQ(blame_override(ovs, "l[01]", "bad"), "bad");
  EXPECT_EQ(blame_override(ovs, "", "bad"), "bad");
  EXPECT_EQ(blame_override({}, "a.b", "bad"), "bad");
}

TEST(YamlUtil, ConvertDocumentRaisesTheLoadersErrorWithTheBlame) {
  const auto convert_a_b = [](const YAML::Node& root) {
    const Reader r("f.yaml");
    double v = 0.0;
    r.read(root["a"]["b"], "a.b", v);
    return v;
  };
  EXPECT_EQ(convert_document<TestError>("a: {b: 1}", "f.yaml", {"a.b=2.5"}, kKind, convert_a_b), 2.5);
  // A PathError from the converter: blamed on the --set that caused it.
  try {
    convert_document<TestError>("a: {b: 1}", "f.yaml", {"a.b=fast"}, kKind, convert_a_b);
    ADD_FAILURE() << "no error";
  } catch (const TestError& e) {
    EXPECT_EQ(e.key_path(), "a.b");
    EXPECT_EQ(e.reason(), "expected a number, got 'fast' (set by the override 'a.b=fast')");
    EXPECT_STREQ(e.what(), "f.yaml: a.b: expected a number, got 'fast' (set by the override 'a.b=fast')");
  }
  // The loader's own error from the converter: blamed the same way.
  try {
    convert_document<TestError>("a: 1", "f.yaml", {"v=0"}, kKind,
                                [](const YAML::Node&) -> int { throw TestError("f.yaml", "v", "must be > 0"); });
    ADD_FAILURE() << "no error";
  } catch (const TestError& e) {
    EXPECT_EQ(e.key_path(), "v");
    EXPECT_EQ(e.reason(), "must be > 0 (set by the override 'v=0')");
  }
  // Errors loading the document or an override: the loader's type, no blame.
  try {
    convert_document<TestError>("a: [1", "f.yaml", {}, kKind, convert_a_b);
    ADD_FAILURE() << "no error";
  } catch (const TestError& e) {
    EXPECT_EQ(e.source(), "f.yaml");
    EXPECT_EQ(e.key_path(), "");
    EXPECT_EQ(e.reason().rfind("YAML syntax error at line 1, column ", 0), 0u) << e.what();
  }
  try {
    convert_document<TestError>("a: 1", "f.yaml", {"l[3]=1"}, kKind, convert_a_b);
    ADD_FAILURE() << "no error";
  } catch (const TestError& e) {
    EXPECT_EQ(e.key_path(), "l");
    EXPECT_EQ(e.reason(), "the override 'l[3]=1': cannot index a missing key, it is not a list");
  }
  // A yaml-cpp exception never escapes as itself.
  try {
    convert_document<TestError>("a: {b: 1}", "f.yaml", {}, kKind,
                                [](const YAML::Node& root) { return root["a"].as<int>(); });
    ADD_FAILURE() << "no error";
  } catch (const TestError& e) {
    EXPECT_EQ(e.source(), "f.yaml");
    EXPECT_EQ(e.key_path(), "");
    EXPECT_EQ(e.reason().rfind("YAML error: ", 0), 0u) << e.what();
  }
}

TEST(YamlUtil, ReadTextFileReadsRegularFilesUpToTheLimit) {
  TempDir dir;
  const std::string file = dir / "a.yaml";
  const std::string text = std::string("a: 1\n\0b", 7) + std::string(200000, 'x');  // binary-safe, several buffers
  write_text(file, text);
  EXPECT_EQ(read_text_file(file, text.size(), "scene file"), text);  // exactly the limit
  write_text(dir / "empty.yaml", "");
  EXPECT_EQ(read_text_file(dir / "empty.yaml", 0, "scene file"), "");

  expect_path_error([&] { read_text_file(file, text.size() - 1, "scene file"); }, file, "",
                    "cannot read scene file: " + std::to_string(text.size()) + " bytes is too large (the limit is " +
                        std::to_string(text.size() - 1) + " bytes)");
  expect_path_error([&] { read_text_file(dir / "missing.yaml", 100, "daemon config file"); }, dir / "missing.yaml", "",
                    "cannot read daemon config file: no such file");
  expect_path_error([&] { read_text_file(dir.path(), 100, "scene file"); }, dir.path(), "",
                    "cannot read scene file: it is a directory");
  const std::string fifo = dir / "fifo";
  ASSERT_EQ(::mkfifo(fifo.c_str(), 0600), 0);
  expect_path_error([&] { read_text_file(fifo, 100, "scene file"); }, fifo, "",
                    "cannot read scene file: not a regular file");
  // The loader's wrapper gives its own error type with the same parts.
  try {
    read_text_file_as<TestError>(dir / "missing.yaml", 100, "scene file");
    ADD_FAILURE() << "no error";
  } catch (const TestError& e) {
    EXPECT_EQ(e.source(), dir / "missing.yaml");
    EXPECT_STREQ(e.what(), (dir / "missing.yaml: cannot read scene file: no such file").c_str());
  }
  EXPECT_EQ(read_text_file_as<TestError>(file, text.size(), "scene file"), text);
}

}  // namespace
}  // namespace tissue::yaml_util
