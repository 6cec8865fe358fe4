// A ControlHandler for tests: records every call with its arguments, answers
// with canned results, and can be told to fail. Thread-safe, because the
// server calls it on its io thread while the test thread reads the record
// (TSan does not see the socket round trip as synchronisation).
#pragma once

#include <mutex>
#include <stdexcept>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "control/control_protocol.hpp"

namespace tissue::control::testing {

struct Call {
  std::string cmd;
  nlohmann::json args;  // {"path": …} or {"key": …, "value": …}; {} otherwise
};

class FakeHandler : public ControlHandler {
 public:
  enum class Failure { kNone, kControlError, kOtherException };

  nlohmann::json status() override { return record("status", nlohmann::json::object(), status_result()); }
  nlohmann::json pause() override { return record("pause", nlohmann::json::object(), {{"paused", true}}); }
  nlohmann::json resume() override { return record("resume", nlohmann::json::object(), {{"paused", false}}); }
  nlohmann::json reset() override { return record("reset", nlohmann::json::object(), {{"sim_time_s", 0.0}}); }
  nlohmann::json load_scene(const std::string& path) override {
    return record("load_scene", {{"path", path}}, {{"scene", path}});
  }
  nlohmann::json set(const std::string& key, const nlohmann::json& value) override {
    return record("set", {{"key", key}, {"value", value}}, {{"key", key}, {"value", value}});
  }
  nlohmann::json shutdown() override { return record("shutdown", nlohmann::json::object(), nullptr); }
  nlohmann::json record_start(const std::string& name) override {
    return record("record_start", {{"name", name}}, {{"file", name}});
  }
  nlohmann::json record_stop() override { return record("record_stop", nlohmann::json::object(), nullptr); }
  nlohmann::json export_x3d(const std::string& name) override {
    return record("export_x3d", {{"name", name}}, {{"file", name}});
  }

  // The status result: depends on how many calls came before, so a test can
  // tell a fresh answer from a replayed one.
  nlohmann::json status_result() const {
    return {{"state", "running"}, {"scene", "cantilever"}, {"calls_before", calls_.size()}};
  }

  void fail_with(Failure f, std::string message) {
    std::lock_guard lock(mutex_);
    failure_ = f;
    failure_message_ = std::move(message);
  }

  std::vector<Call> calls() const {
    std::lock_guard lock(mutex_);
    return calls_;
  }
  std::size_t call_count() const {
    std::lock_guard lock(mutex_);
    return calls_.size();
  }

 private:
  nlohmann::json record(const std::string& cmd, nlohmann::json args, nlohmann::json result) {
    std::lock_guard lock(mutex_);
    calls_.push_back({cmd, std::move(args)});
    if (failure_ == Failure::kControlError) throw ControlError(failure_message_);
    if (failure_ == Failure::kOtherException) throw std::runtime_error(failure_message_);
    return result;
  }

  mutable std::mutex mutex_;
  std::vector<Call> calls_;
  Failure failure_ = Failure::kNone;
  std::string failure_message_;
};

}  // namespace tissue::control::testing
