#include "scene/scene_names.hpp"

#include <gtest/gtest.h>

#include <set>
#include <string_view>

namespace tissue::scene {
namespace {

// Every enumerator from first to last has its own word, and the word reads
// back as the enumerator: a choice added to an enum but not to its table, or
// two choices sharing a word, fails here rather than in a scene file.
template <class E, std::size_t N>
void expect_round_trip(const NameTable<E, N>& table, E last) {
  std::set<std::string_view> words;
  for (int i = 0; i <= static_cast<int>(last); ++i) {
    const auto value = static_cast<E>(i);
    const std::string_view word = name_of(table, value);
    EXPECT_NE(word, "?") << "enumerator " << i << " has no word";
    EXPECT_EQ(value_named(table, word), value) << word;
    words.insert(word);
  }
  EXPECT_EQ(words.size(), static_cast<std::size_t>(last) + 1);
  EXPECT_EQ(table.size(), words.size()) << "a word names no enumerator";
}

TEST(SceneNames, EveryChoiceHasOneWordThatReadsBack) {
  expect_round_trip(kStiffnessLawNames, StiffnessLaw::kPaper);
  expect_round_trip(kDampingLawNames, DampingLaw::kPaper);
  expect_round_trip(kRefineCriterionNames, RefineCriterion::kStretch);
  expect_round_trip(kIntegratorNames, IntegratorKind::kProjective);
  expect_round_trip(kCgPreconditionerNames, CgPreconditioner::kTwoLevel);
  expect_round_trip(kExplicitPrecisionNames, ExplicitPrecision::kFloat);
}

TEST(SceneNames, TheWordsAreTheScenesFormats) {  // docs/scene-format.md
  EXPECT_EQ(name_of(kIntegratorNames, IntegratorKind::kImplicit), "implicit");
  EXPECT_EQ(name_of(kCgPreconditionerNames, CgPreconditioner::kTwoLevel), "two_level");
  EXPECT_EQ(name_of(kRefineCriterionNames, RefineCriterion::kStrainEnergy), "strain_energy");
  EXPECT_FALSE(value_named(kIntegratorNames, "rk4").has_value());
  EXPECT_FALSE(value_named(kIntegratorNames, "Implicit").has_value());  // words are case-sensitive
  EXPECT_FALSE(value_named(kIntegratorNames, "").has_value());
}

}  // namespace
}  // namespace tissue::scene
