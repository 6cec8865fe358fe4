// Keeps proto/lcm/*.lcm and proto/idl/*.idl one schema: every message and
// every field (name, element type, scalar / fixed array of N / variable
// length, in declaration order) must exist in both. LCM variable arrays need
// an explicit length field (int32_t vertex_count; ... x[vertex_count]); DDS
// sequences carry their length, so LCM fields used as a dimension are
// compared by their role, not as fields.
//
// The parsers understand the subset proto/ uses (package/module, struct,
// primitive fields, one array dimension) and fail loudly on anything else,
// so a new construct is a test failure to extend, never a silent skip.
#include <gtest/gtest.h>

#include <algorithm>
#include <cctype>
#include <filesystem>
#include <fstream>
#include <map>
#include <set>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

namespace {

struct Field {
  std::string name;
  std::string type;  // normalised: int8 uint8 int16 int32 int64 float32 float64 bool string ...
  enum class Shape { kScalar, kFixed, kVariable } shape = Shape::kScalar;
  int fixed_length = 0;      // kFixed
  std::string length_field;  // kVariable, LCM only
};

struct Message {
  std::string name;
  std::string source;  // file, for messages
  std::vector<Field> fields;
};

using Schema = std::map<std::string, Message>;

std::string strip_comments(const std::string& text) {
  std::string out;
  for (std::size_t i = 0; i < text.size();) {
    if (text.compare(i, 2, "//") == 0) {
      while (i < text.size() && text[i] != '\n') ++i;
    } else if (text.compare(i, 2, "/*") == 0) {
      const std::size_t end = text.find("*/", i + 2);
      if (end == std::string::npos) throw std::runtime_error("unterminated /* comment");
      i = end + 2;
      out += ' ';
    } else {
      out += text[i++];
    }
  }
  return out;
}

class Tokens {
 public:
  Tokens(const std::string& text, std::string source) : source_(std::move(source)) {
    const std::string t = strip_comments(text);
    for (std::size_t i = 0; i < t.size();) {
      const unsigned char c = static_cast<unsigned char>(t[i]);
      if (std::isspace(c)) {
        ++i;
      } else if (std::isalnum(c) || c == '_') {
        std::size_t j = i;
        while (j < t.size() && (std::isalnum(static_cast<unsigned char>(t[j])) || t[j] == '_')) ++j;
        tokens_.push_back(t.substr(i, j - i));
        i = j;
      } else {
        tokens_.push_back(std::string(1, t[i]));
        ++i;
      }
    }
  }
  bool done() const { return pos_ >= tokens_.size(); }
  const std::string& peek() const {
    if (done()) fail("unexpected end of file");
    return tokens_[pos_];
  }
  std::string next() {
    const std::string t = peek();
    ++pos_;
    return t;
  }
  void expect(const std::string& want) {
    const std::string got = next();
    if (got != want) fail("expected '" + want + "', got '" + got + "'");
  }
  bool accept(const std::string& want) {
    if (!done() && tokens_[pos_] == want) {
      ++pos_;
      return true;
    }
    return false;
  }
  std::string identifier() {
    const std::string t = next();
    if (!(std::isalpha(static_cast<unsigned char>(t[0])) || t[0] == '_')) fail("expected a name, got '" + t + "'");
    return t;
  }
  [[noreturn]] void fail(const std::string& why) const {
    throw std::runtime_error(source_ + ": " + why + " (token " + std::to_string(pos_) + ")");
  }
  const std::string& source() const { return source_; }

 private:
  std::string source_;
  std::vector<std::string> tokens_;
  std::size_t pos_ = 0;
};

bool is_integer(const std::string& type) { return type.rfind("int", 0) == 0 || type.rfind("uint", 0) == 0; }

int parse_length(Tokens& t, const std::string& token) {
  if (token.empty() || !std::all_of(token.begin(), token.end(), [](char c) { return std::isdigit(c); }))
    t.fail("expected a fixed array length, got '" + token + "'");
  return std::stoi(token);
}

// package tissue; struct name { type field[dim]; ... }
std::vector<Message> parse_lcm(const std::string& text, const std::string& source, std::string* package) {
  static const std::map<std::string, std::string> kTypes{
      {"int8_t", "int8"},   {"int16_t", "int16"},  {"int32_t", "int32"}, {"int64_t", "int64"}, {"byte", "uint8"},
      {"float", "float32"}, {"double", "float64"}, {"boolean", "bool"},  {"string", "string"}};
  Tokens t(text, source);
  std::vector<Message> messages;
  if (t.accept("package")) {
    *package = t.identifier();
    if (t.peek() == ".") t.fail("nested packages are not in the supported subset");
    t.expect(";");
  }
  while (!t.done()) {
    t.expect("struct");
    Message m;
    m.name = t.identifier();
    m.source = source;
    t.expect("{");
    while (!t.accept("}")) {
      if (t.peek() == "const") t.fail("LCM constants are not in the supported subset");
      const std::string lcm_type = t.identifier();
      const auto type = kTypes.find(lcm_type);
      if (type == kTypes.end()) t.fail("type '" + lcm_type + "' is not in the supported subset");
      Field f;
      f.type = type->second;
      f.name = t.identifier();
      if (t.accept("[")) {
        const std::string dim = t.next();
        if (std::isdigit(static_cast<unsigned char>(dim[0]))) {
          f.shape = Field::Shape::kFixed;
          f.fixed_length = parse_length(t, dim);
        } else {
          f.shape = Field::Shape::kVariable;
          f.length_field = dim;
        }
        t.expect("]");
        if (t.peek() == "[") t.fail("multi-dimensional arrays are not in the supported subset");
      }
      t.expect(";");
      m.fields.push_back(f);
    }
    messages.push_back(std::move(m));
  }
  return messages;
}

// module tissue { struct name { type field[N]; sequence<type> field; }; };
std::vector<Message> parse_idl(const std::string& text, const std::string& source, std::string* module) {
  static const std::map<std::string, std::string> kTypes{{"octet", "uint8"},
                                                         {"int8", "int8"},
                                                         {"uint8", "uint8"},
                                                         {"short", "int16"},
                                                         {"long", "int32"},
                                                         {"long long", "int64"},
                                                         {"unsigned short", "uint16"},
                                                         {"unsigned long", "uint32"},
                                                         {"unsigned long long", "uint64"},
                                                         {"float", "float32"},
                                                         {"double", "float64"},
                                                         {"boolean", "bool"},
                                                         {"string", "string"}};
  Tokens t(text, source);
  auto read_type = [&]() {
    std::string name = t.identifier();
    if (name == "unsigned") name += " " + t.identifier();
    if ((name == "long" || name == "unsigned long") && t.peek() == "long") name += " " + t.next();
    const auto type = kTypes.find(name);
    if (type == kTypes.end()) t.fail("type '" + name + "' is not in the supported subset");
    return type->second;
  };
  std::vector<Message> messages;
  t.expect("module");
  *module = t.identifier();
  t.expect("{");
  while (!t.accept("}")) {
    t.expect("struct");
    Message m;
    m.name = t.identifier();
    m.source = source;
    t.expect("{");
    while (!t.accept("}")) {
      Field f;
      if (t.accept("sequence")) {
        t.expect("<");
        f.type = read_type();
        if (t.peek() == ",") t.fail("bounded sequences are not in the supported subset");
        t.expect(">");
        f.shape = Field::Shape::kVariable;
      } else {
        f.type = read_type();
      }
      f.name = t.identifier();
      if (t.accept("[")) {
        if (f.shape == Field::Shape::kVariable) t.fail("arrays of sequences are not in the supported subset");
        f.shape = Field::Shape::kFixed;
        f.fixed_length = parse_length(t, t.next());
        t.expect("]");
        if (t.peek() == "[") t.fail("multi-dimensional arrays are not in the supported subset");
      }
      t.expect(";");
      m.fields.push_back(f);
    }
    t.expect(";");
    messages.push_back(std::move(m));
  }
  t.expect(";");
  if (!t.done()) t.fail("text after the module");
  return messages;
}

// Drops LCM length fields (those named as a dimension), checking they are
// integer scalars declared before their array.
std::vector<std::string> remove_length_fields(Message& m) {
  std::vector<std::string> problems;
  std::set<std::string> lengths;
  for (std::size_t i = 0; i < m.fields.size(); ++i) {
    const Field& f = m.fields[i];
    if (f.shape != Field::Shape::kVariable) continue;
    const auto it = std::find_if(m.fields.begin(), m.fields.begin() + static_cast<long>(i),
                                 [&](const Field& g) { return g.name == f.length_field; });
    if (it == m.fields.begin() + static_cast<long>(i))
      problems.push_back(m.source + ": " + m.name + "." + f.name + ": length field '" + f.length_field +
                         "' is not declared before it");
    else if (!is_integer(it->type) || it->shape != Field::Shape::kScalar)
      problems.push_back(m.source + ": " + m.name + "." + f.name + ": length field '" + f.length_field +
                         "' is not an integer scalar");
    lengths.insert(f.length_field);
  }
  std::erase_if(m.fields, [&](const Field& f) { return lengths.count(f.name) > 0; });
  return problems;
}

std::string describe(const Field& f) {
  switch (f.shape) {
    case Field::Shape::kScalar:
      return f.type;
    case Field::Shape::kFixed:
      return f.type + "[" + std::to_string(f.fixed_length) + "]";
    case Field::Shape::kVariable:
      return f.type + "[variable]";
  }
  return "?";
}

// Every difference between the two schemas, as readable lines.
std::vector<std::string> compare(Schema lcm, const Schema& idl) {
  std::vector<std::string> diffs;
  for (auto& [name, m] : lcm) {
    for (const std::string& p : remove_length_fields(m)) diffs.push_back(p);
  }
  for (const auto& [name, m] : lcm)
    if (!idl.count(name)) diffs.push_back("message '" + name + "' is in " + m.source + " but in no .idl");
  for (const auto& [name, m] : idl)
    if (!lcm.count(name)) diffs.push_back("message '" + name + "' is in " + m.source + " but in no .lcm");
  for (const auto& [name, l] : lcm) {
    const auto it = idl.find(name);
    if (it == idl.end()) continue;
    const Message& d = it->second;
    auto find = [](const Message& m, const std::string& field) -> const Field* {
      for (const Field& f : m.fields)
        if (f.name == field) return &f;
      return nullptr;
    };
    for (const Field& f : l.fields) {
      const Field* g = find(d, f.name);
      if (!g)
        diffs.push_back(name + "." + f.name + " is in " + l.source + " but not in " + d.source);
      else if (describe(f) != describe(*g))
        diffs.push_back(name + "." + f.name + ": " + describe(f) + " in " + l.source + " but " + describe(*g) + " in " +
                        d.source);
    }
    for (const Field& g : d.fields)
      if (!find(l, g.name)) diffs.push_back(name + "." + g.name + " is in " + d.source + " but not in " + l.source);
    std::vector<std::string> lcm_order, idl_order;
    for (const Field& f : l.fields)
      if (find(d, f.name)) lcm_order.push_back(f.name);
    for (const Field& g : d.fields)
      if (find(l, g.name)) idl_order.push_back(g.name);
    if (lcm_order != idl_order) diffs.push_back(name + ": fields are declared in a different order");
  }
  return diffs;
}

std::string read_text(const std::filesystem::path& path) {
  std::ifstream in(path);
  if (!in) throw std::runtime_error("cannot read " + path.string());
  std::ostringstream s;
  s << in.rdbuf();
  return s.str();
}

// Loads every file of one IDL; each file holds one message named like the
// file (proto/CMakeLists.txt generates per message name) in package/module tissue.
Schema load(const std::string& dir, const std::string& extension, bool is_lcm) {
  Schema schema;
  std::vector<std::filesystem::path> files;
  for (const auto& entry : std::filesystem::directory_iterator(dir))
    if (entry.path().extension() == extension) files.push_back(entry.path());
  std::sort(files.begin(), files.end());
  for (const auto& path : files) {
    std::string scope;
    const std::string text = read_text(path);
    std::vector<Message> messages =
        is_lcm ? parse_lcm(text, path.string(), &scope) : parse_idl(text, path.string(), &scope);
    EXPECT_EQ(scope, "tissue") << path << ": package/module must be 'tissue'";
    EXPECT_EQ(messages.size(), 1u) << path << ": one message per file";
    for (Message& m : messages) {
      EXPECT_EQ(m.name, path.stem().string()) << path << ": the file must be named after its message";
      EXPECT_FALSE(schema.count(m.name)) << m.name << " is defined twice";
      schema[m.name] = std::move(m);
    }
  }
  return schema;
}

Schema parse_one_lcm(const std::string& text) {
  std::string package;
  Schema s;
  for (Message& m : parse_lcm(text, "test.lcm", &package)) s[m.name] = m;
  return s;
}

Schema parse_one_idl(const std::string& text) {
  std::string module;
  Schema s;
  for (Message& m : parse_idl(text, "test.idl", &module)) s[m.name] = m;
  return s;
}

std::string joined(const std::vector<std::string>& lines) {
  std::string out;
  for (const std::string& l : lines) out += "  " + l + "\n";
  return out;
}

TEST(SchemaDrift, LcmAndIdlDefineTheSameMessagesAndFields) {
  const Schema lcm = load(TISSUE_PROTO_LCM_DIR, ".lcm", true);
  const Schema idl = load(TISSUE_PROTO_IDL_DIR, ".idl", false);
  for (const char* name : {"surface_mesh", "haptic_state", "sim_stats", "device_packet"}) {
    EXPECT_TRUE(lcm.count(name)) << name;
    EXPECT_TRUE(idl.count(name)) << name;
  }
  const std::vector<std::string> diffs = compare(lcm, idl);
  EXPECT_TRUE(diffs.empty()) << "proto/lcm and proto/idl differ:\n" << joined(diffs);
}

// The checker itself: each kind of drift it exists for is reported.
const char* kLcm = R"(package tissue;
struct m {
  double time_s;      // comment
  int32_t n;          /* length */
  float v[n];
  double p[3];
  byte level;
})";
const char* kIdl = R"(module tissue { struct m {
  double time_s;
  sequence<float> v;
  double p[3];
  octet level;
}; };)";

TEST(SchemaDrift, EquivalentDefinitionsPass) {
  EXPECT_TRUE(compare(parse_one_lcm(kLcm), parse_one_idl(kIdl)).empty())
      << joined(compare(parse_one_lcm(kLcm), parse_one_idl(kIdl)));
}

TEST(SchemaDrift, ReportsAMissingField) {
  const std::string idl = std::string(kIdl).replace(std::string(kIdl).find("octet level;"), 12, "");
  const auto diffs = compare(parse_one_lcm(kLcm), parse_one_idl(idl));
  ASSERT_EQ(diffs.size(), 1u) << joined(diffs);
  EXPECT_NE(diffs[0].find("m.level is in test.lcm but not in test.idl"), std::string::npos) << diffs[0];
}

TEST(SchemaDrift, ReportsAnExtraFieldAndAMissingMessage) {
  std::string idl = kIdl;
  idl.replace(idl.find("octet level;"), 12, "octet level; long extra_count;");
  idl.replace(idl.find("}; };"), 5, "}; struct only_dds { double x; }; };");
  const std::string diffs = joined(compare(parse_one_lcm(kLcm), parse_one_idl(idl)));
  EXPECT_NE(diffs.find("m.extra_count is in test.idl but not in test.lcm"), std::string::npos) << diffs;
  EXPECT_NE(diffs.find("message 'only_dds' is in test.idl but in no .lcm"), std::string::npos) << diffs;
}

TEST(SchemaDrift, ReportsElementTypeMismatches) {
  std::string idl = kIdl;
  idl.replace(idl.find("sequence<float>"), 15, "sequence<double>");
  idl.replace(idl.find("octet level"), 5, "long ");
  const auto diffs = compare(parse_one_lcm(kLcm), parse_one_idl(idl));
  ASSERT_EQ(diffs.size(), 2u) << joined(diffs);
  EXPECT_NE(diffs[0].find("m.v: float32[variable] in test.lcm but float64[variable] in test.idl"), std::string::npos)
      << diffs[0];
  EXPECT_NE(diffs[1].find("m.level: uint8 in test.lcm but int32 in test.idl"), std::string::npos) << diffs[1];
}

TEST(SchemaDrift, ReportsArrayShapeMismatches) {
  std::string idl = kIdl;
  idl.replace(idl.find("double p[3]"), 11, "double p[4]");
  idl.replace(idl.find("sequence<float> v"), 17, "float v[3]");
  const auto diffs = compare(parse_one_lcm(kLcm), parse_one_idl(idl));
  ASSERT_EQ(diffs.size(), 2u) << joined(diffs);
  EXPECT_NE(diffs[0].find("m.v: float32[variable] in test.lcm but float32[3]"), std::string::npos) << diffs[0];
  EXPECT_NE(diffs[1].find("m.p: float64[3] in test.lcm but float64[4]"), std::string::npos) << diffs[1];
  std::string scalar = kIdl;
  scalar.replace(scalar.find("double p[3]"), 11, "double p");
  EXPECT_EQ(compare(parse_one_lcm(kLcm), parse_one_idl(scalar)).size(), 1u);
}

TEST(SchemaDrift, ReportsOrderAndBadLengthFields) {
  std::string idl = kIdl;
  idl.replace(idl.find("double time_s;"), 14, "");
  idl.replace(idl.find("octet level;"), 12, "octet level; double time_s;");
  EXPECT_NE(joined(compare(parse_one_lcm(kLcm), parse_one_idl(idl))).find("different order"), std::string::npos);

  std::string lcm = kLcm;
  lcm.replace(lcm.find("int32_t n;"), 10, "double n;");
  EXPECT_NE(joined(compare(parse_one_lcm(lcm), parse_one_idl(kIdl))).find("is not an integer scalar"),
            std::string::npos);
}

TEST(SchemaDrift, UnsupportedConstructsFailLoudly) {
  EXPECT_THROW(parse_one_lcm("package tissue; struct m { int32_t n; float v[n][3]; }"), std::runtime_error);
  EXPECT_THROW(parse_one_lcm("package tissue; struct m { other.type x; }"), std::runtime_error);
  EXPECT_THROW(parse_one_lcm("package tissue; struct m { const int32_t K = 1; }"), std::runtime_error);
  EXPECT_THROW(parse_one_idl("module tissue { struct m { sequence<float, 10> v; }; };"), std::runtime_error);
  EXPECT_THROW(parse_one_idl("module tissue { struct m { wchar c; }; };"), std::runtime_error);
  EXPECT_THROW(parse_one_idl("module tissue { struct m { double x; };"), std::runtime_error);
}

}  // namespace
