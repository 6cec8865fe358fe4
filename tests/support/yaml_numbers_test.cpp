#include "support/yaml_numbers.hpp"

#include <gtest/gtest.h>

namespace tissue::testing {
namespace {

TEST(YamlNumbers, FindsBlockAndFlowNumbersWithTheirKeysAndSkipsComments) {
  const std::string text =
      "a: 1.5e4   # 7 in a comment\n"
      "list: [0, -0.25, 3]\n"
      "# b: 9\n"
      "- {time_s: 2, position_m: [0.1, 0.2]}\n"
      "name: x2\n";
  const std::vector<YamlNumber> n = yaml_numbers(text);
  ASSERT_EQ(n.size(), 7u);
  const std::vector<std::pair<std::string, std::string>> want = {
      {"a", "1.5e4"},  {"list", "0"},         {"list", "-0.25"},    {"list", "3"},
      {"time_s", "2"}, {"position_m", "0.1"}, {"position_m", "0.2"}};
  for (std::size_t i = 0; i < want.size(); ++i) {
    EXPECT_EQ(n[i].key, want[i].first) << i;
    EXPECT_EQ(n[i].text, want[i].second) << i;
    EXPECT_EQ(text.substr(n[i].offset, n[i].length), n[i].text) << i;
  }
}

}  // namespace
}  // namespace tissue::testing
