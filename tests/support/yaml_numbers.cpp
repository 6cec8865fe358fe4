#include "support/yaml_numbers.hpp"

#include <regex>

namespace tissue::testing {

std::vector<YamlNumber> yaml_numbers(const std::string& text) {
  static const std::regex number(R"((:\s+|\[\s*|,\s*)(-?[0-9][0-9.eE+-]*))");
  static const std::regex key_before(R"(([A-Za-z_][A-Za-z_0-9]*):)");
  std::vector<YamlNumber> out;
  for (auto it = std::sregex_iterator(text.begin(), text.end(), number); it != std::sregex_iterator(); ++it) {
    YamlNumber n;
    n.offset = static_cast<std::size_t>(it->position(2));
    n.length = static_cast<std::size_t>(it->length(2));
    n.text = it->str(2);
    const std::size_t line_start = n.offset == 0 ? 0 : text.rfind('\n', n.offset - 1) + 1;
    const std::string before = text.substr(line_start, n.offset - line_start);
    if (before.find('#') != std::string::npos) continue;  // in a comment
    for (auto k = std::sregex_iterator(before.begin(), before.end(), key_before); k != std::sregex_iterator(); ++k)
      n.key = (*k)[1];
    if (!n.key.empty()) out.push_back(n);
  }
  return out;
}

}  // namespace tissue::testing
