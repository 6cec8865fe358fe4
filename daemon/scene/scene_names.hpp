// The words a scene file uses for each choice (docs/scene-format.md), kept in
// one place: the scene loader reads them, and the trade study's options, CSV
// and plots write and parse the same words, so a new choice is named once.
#pragma once

#include <array>
#include <cstddef>
#include <optional>
#include <string_view>
#include <utility>

#include "scene/scene.hpp"

namespace tissue::scene {

template <class E, std::size_t N>
using NameTable = std::array<std::pair<std::string_view, E>, N>;

inline constexpr NameTable<StiffnessLaw, 2> kStiffnessLawNames{
    {{"isotropic", StiffnessLaw::kIsotropic}, {"paper", StiffnessLaw::kPaper}}};
inline constexpr NameTable<DampingLaw, 2> kDampingLawNames{
    {{"rayleigh", DampingLaw::kRayleigh}, {"paper", DampingLaw::kPaper}}};
inline constexpr NameTable<RefineCriterion, 2> kRefineCriterionNames{
    {{"strain_energy", RefineCriterion::kStrainEnergy}, {"stretch", RefineCriterion::kStretch}}};
inline constexpr NameTable<IntegratorKind, 3> kIntegratorNames{{{"explicit", IntegratorKind::kExplicit},
                                                                {"implicit", IntegratorKind::kImplicit},
                                                                {"projective", IntegratorKind::kProjective}}};
inline constexpr NameTable<CgPreconditioner, 3> kCgPreconditionerNames{{{"auto", CgPreconditioner::kAuto},
                                                                        {"jacobi", CgPreconditioner::kJacobi},
                                                                        {"two_level", CgPreconditioner::kTwoLevel}}};
inline constexpr NameTable<ExplicitPrecision, 2> kExplicitPrecisionNames{
    {{"double", ExplicitPrecision::kDouble}, {"float", ExplicitPrecision::kFloat}}};

// The word for `value`. Every enumerator has one (scene_names_test checks),
// and every word is a string literal, so data() is NUL-terminated.
template <class E, std::size_t N>
constexpr std::string_view name_of(const NameTable<E, N>& table, E value) {
  for (const auto& [name, v] : table)
    if (v == value) return name;
  return "?";
}

// The value a word names, or nothing for a word not in the table.
template <class E, std::size_t N>
constexpr std::optional<E> value_named(const NameTable<E, N>& table, std::string_view word) {
  for (const auto& [name, v] : table)
    if (name == word) return v;
  return std::nullopt;
}

}  // namespace tissue::scene
