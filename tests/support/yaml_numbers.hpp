// The numbers written in a YAML text, block or flow style, each with where it
// is and the key it is the value (or a list element) of: for the sweeps that
// replace every number of a shipped file, one at a time, by an extreme and
// check the loader's answer names that key.
#pragma once

#include <cstddef>
#include <string>
#include <vector>

namespace tissue::testing {

struct YamlNumber {
  std::size_t offset = 0;  // into the text
  std::size_t length = 0;
  std::string text;  // as written ("5.0e4", "-0.01")
  std::string key;   // the nearest key before it on its line ("youngs_modulus_Pa", "position_m")
};

// Numbers after "key: ", "[" or ", " on their line; none in a comment.
std::vector<YamlNumber> yaml_numbers(const std::string& text);

}  // namespace tissue::testing
