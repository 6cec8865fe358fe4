#include "service/sim_runner.hpp"

namespace tissue::service {

SimRunner::SimRunner(const scene::Scene& scene) : sim_(std::make_unique<physics::Simulation>(scene)) {
  // No tool seen yet: park it far above the object so nothing engages.
  query_.tool_m = physics::Vec3(0.0, 0.0, 1e3);
}

void SimRunner::apply_tool(std::span<const haptics::ToolSample> samples, RunnerStep* out) {
  physics::Vec3 force_sum = physics::Vec3::Zero();
  int ticks = 0;  // the trusted ticks covering the step, touching or not
  int contacts = 0;
  const haptics::ToolSample* newest_contact = nullptr;
  for (const haptics::ToolSample& s : samples) {
    if (!s.proxy_position_m.allFinite()) continue;  // never trust another thread's numbers blindly
    query_.tool_m = s.proxy_position_m;
    if (s.contact && !s.force_on_object_N.allFinite()) continue;
    ++ticks;
    if (!s.contact) continue;
    force_sum += s.force_on_object_N;
    ++contacts;
    newest_contact = &s;
  }
  out->samples_used = static_cast<int>(samples.size());
  physics::Adaptivity* adaptivity = sim_->adaptivity();
  if (contacts == 0) {
    // No contact in any tick since the last step (or no haptic ticks at all):
    // the tool is off the object.
    if (!samples.empty()) {
      sim_->clear_tool_force();
      if (adaptivity) adaptivity->unfreeze();
    }
    out->tool_pushing = sim_->tool_force_N().squaredNorm() > 0.0;
    return;
  }
  // The mean over all the ticks, those off the object counting as zero, is
  // the impulse-consistent force over the step: one touching tick of five
  // gives a fifth of its force, not all of it for the whole step.
  const physics::Vec3 mean_N = force_sum / ticks;
  query_.contact_node = newest_contact->contact_node;
  query_.contact_weight = newest_contact->contact_weight;
  out->tool_pushing = sim_->set_tool_force(query_.contact_node, query_.contact_weight, mean_N);
  if (!out->tool_pushing) sim_->clear_tool_force();
  if (adaptivity) {
    if (out->tool_pushing)
      adaptivity->freeze_sphere(newest_contact->proxy_position_m, sim_->scene().tool->freeze_radius_m);
    else
      adaptivity->unfreeze();
  }
}

void SimRunner::move_tool(std::span<const haptics::ToolSample> samples) {
  for (const haptics::ToolSample& s : samples)
    if (s.proxy_position_m.allFinite()) query_.tool_m = s.proxy_position_m;  // never trust another thread's numbers
}

bool SimRunner::refresh_model(std::span<const haptics::ToolSample> samples, haptics::LocalModel* model) {
  if (!sim_->has_tool() || !model) return false;
  const physics::Vec3 before_m = query_.tool_m;
  move_tool(samples);
  if (frozen_model_built_ && query_.tool_m == before_m) return false;
  builder_.build(*sim_, query_, model, /*frozen=*/true);
  frozen_model_built_ = true;
  return true;
}

RunnerStep SimRunner::step(std::span<const haptics::ToolSample> samples, haptics::LocalModel* model) {
  RunnerStep out;
  frozen_model_built_ = false;
  const bool tool = sim_->has_tool();
  if (tool) apply_tool(samples, &out);
  const physics::StepResult r = sim_->step();
  out.ok = r.ok;
  out.error = r.error;
  out.adapted = r.adapted;
  if (tool && model) {
    builder_.build(*sim_, query_, model);
    out.model_built = true;
  }
  return out;
}

}  // namespace tissue::service
