// The sim thread's work for one step, without the thread (tests drive it
// directly; service/sim_thread runs it paced to the wall clock):
//   tool samples from the haptic loop -> tool force on the mesh (equal and
//   opposite to what the user felt, averaged over the samples since the last
//   step, those off the object counting as zero) -> freeze adaptivity under
//   an engaged tool -> Simulation::step()
//   -> rebuild the LocalModel around the tool.
// Paused, refresh_model() keeps the LocalModel around the tool without a step.
// A scene without a tool runs none of the tool code (no samples expected, no
// local model built).
#pragma once

#include <cstdint>
#include <memory>
#include <span>
#include <string>

#include "haptics/local_model.hpp"
#include "physics/simulation.hpp"
#include "service/local_model_builder.hpp"

namespace tissue::service {

struct RunnerStep {
  bool ok = true;
  std::string error;          // why the step was refused (state kept)
  bool model_built = false;   // *model was rewritten (scenes with a tool)
  bool tool_pushing = false;  // a tool force was applied in this step
  int samples_used = 0;
  physics::AdaptStats adapted;
};

class SimRunner {
 public:
  // Throws std::invalid_argument when the scene cannot be simulated.
  explicit SimRunner(const scene::Scene& scene);

  // One step. `samples` are the haptic ticks since the last call, oldest
  // first (may be empty). When the scene has a tool, `model` receives the new
  // local model (version and built_ns are the caller's to stamp).
  RunnerStep step(std::span<const haptics::ToolSample> samples, haptics::LocalModel* model);

  // Paused: the simulation is neither stepped nor pushed (the samples'
  // contacts and forces are ignored). Moves the tool to the newest of
  // `samples` (none: where it was) and rebuilds `model` around it on the
  // frozen surface, a rigid wall standing still (LocalModelBuilder::build,
  // frozen): the patch follows the hand, which would otherwise meet the edge
  // of the patch built where the tool was at the pause. Returns whether
  // `model` was rewritten: not when the scene has no tool, nor when the last
  // call already rebuilt it (no step since) with the tool where it is.
  bool refresh_model(std::span<const haptics::ToolSample> samples, haptics::LocalModel* model);

  physics::Simulation& simulation() { return *sim_; }
  const physics::Simulation& simulation() const { return *sim_; }

 private:
  void apply_tool(std::span<const haptics::ToolSample> samples, RunnerStep* out);
  // The newest finite proxy position among `samples` becomes the tool's.
  void move_tool(std::span<const haptics::ToolSample> samples);

  std::unique_ptr<physics::Simulation> sim_;
  LocalModelBuilder builder_;
  PatchQuery query_;
  bool frozen_model_built_ = false;  // refresh_model rebuilt the model, no step since
};

}  // namespace tissue::service
