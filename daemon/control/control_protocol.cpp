#include "control/control_protocol.hpp"

#include <algorithm>
#include <array>
#include <exception>
#include <set>
#include <string>
#include <utility>
#include <vector>

#include "scene/yaml_util.hpp"

namespace tissue::control {

namespace {

using nlohmann::json;
using yaml_util::printable;

// Structured values nested deeper than `limit` levels.
bool deeper_than(const json& j, int limit) {
  if (!j.is_structured()) return false;
  if (limit <= 0) return true;
  for (const json& child : j)
    if (deeper_than(child, limit - 1)) return true;
  return false;
}

std::string type_name(const json& j) {
  switch (j.type()) {
    case json::value_t::null:
      return "null";
    case json::value_t::boolean:
      return "a boolean";
    case json::value_t::string:
      return "a string";
    case json::value_t::number_integer:
    case json::value_t::number_unsigned:
    case json::value_t::number_float:
      return "a number";
    case json::value_t::array:
      return "an array";
    case json::value_t::object:
      return "an object";
    default:
      return "an unsupported value";
  }
}

std::string ok_line(const json& id, const json& result) {
  const json body = result.is_null() ? json::object() : result;
  return "{\"id\":" + to_line(id) + ",\"ok\":true,\"result\":" + to_line(body) + "}";
}

std::string error_line(const json& id, const std::string& message) {
  return "{\"id\":" + to_line(id) + ",\"ok\":false,\"error\":" + to_line(json(message)) + "}";
}

// Thrown while checking a request; becomes the response's error.
struct BadRequest {
  std::string message;
};

struct Command {
  std::string_view name;
  std::array<std::string_view, 2> args;  // besides "id" and "cmd"; unused slots empty

  bool takes(std::string_view arg) const {
    return !arg.empty() && std::find(args.begin(), args.end(), arg) != args.end();
  }
};

constexpr std::array<Command, 10> kCommands{{{"status", {}},
                                             {"pause", {}},
                                             {"resume", {}},
                                             {"reset", {}},
                                             {"load_scene", {"path"}},
                                             {"set", {"key", "value"}},
                                             {"shutdown", {}},
                                             {"record_start", {"name"}},
                                             {"record_stop", {}},
                                             {"export_x3d", {"name"}}}};

std::string allowed_list(const Command& c) {
  std::string out = "id, cmd";
  for (const auto a : c.args) {
    if (a.empty()) continue;
    out += ", ";
    out += a;
  }
  return out;
}

const json& required(const json& request, const char* key, const std::string& cmd) {
  const auto it = request.find(key);
  if (it == request.end()) throw BadRequest{"command '" + cmd + "' needs argument '" + key + "'"};
  return *it;
}

std::string required_string(const json& request, const char* key, const std::string& cmd, std::size_t max_bytes) {
  const json& v = required(request, key, cmd);
  if (!v.is_string())
    throw BadRequest{"argument '" + std::string(key) + "' of '" + cmd + "' must be a string, got " + type_name(v)};
  const std::string& s = v.get_ref<const std::string&>();
  if (s.empty()) throw BadRequest{"argument '" + std::string(key) + "' of '" + cmd + "' must not be empty"};
  if (s.size() > max_bytes)
    throw BadRequest{"argument '" + std::string(key) + "' of '" + cmd + "' is too long (" + std::to_string(s.size()) +
                     " bytes, at most " + std::to_string(max_bytes) + ")"};
  if (s.find('\0') != std::string::npos)
    throw BadRequest{"argument '" + std::string(key) + "' of '" + cmd + "' must not contain a NUL character"};
  return s;
}

json dispatch(const Command& c, const json& request, ControlHandler& handler) {
  const std::string cmd(c.name);
  if (cmd == "status") return handler.status();
  if (cmd == "pause") return handler.pause();
  if (cmd == "resume") return handler.resume();
  if (cmd == "reset") return handler.reset();
  if (cmd == "shutdown") return handler.shutdown();
  if (cmd == "load_scene") return handler.load_scene(required_string(request, "path", cmd, kMaxPathBytes));
  if (cmd == "record_stop") return handler.record_stop();
  if (cmd == "export_x3d")
    return handler.export_x3d(request.contains("name") ? required_string(request, "name", cmd, kMaxFileNameBytes)
                                                       : std::string());
  if (cmd == "record_start")
    return handler.record_start(request.contains("name") ? required_string(request, "name", cmd, kMaxFileNameBytes)
                                                         : std::string());
  if (cmd == "set") {
    const std::string key = required_string(request, "key", cmd, kMaxKeyPathBytes);
    if (!is_valid_key_path(key))
      throw BadRequest{"argument 'key' of 'set' is not a key path: " + printable(key) +
                       " (expected names joined by '.', e.g. material.youngs_modulus_Pa or loads[0].total_force_N[2])"};
    const json& value = required(request, "value", cmd);
    if (deeper_than(value, kMaxJsonDepth))
      throw BadRequest{"argument 'value' of 'set' is nested too deeply (more than " + std::to_string(kMaxJsonDepth) +
                       " levels)"};
    return handler.set(key, value);
  }
  // kCommands and this function list the same names.
  throw BadRequest{"command '" + cmd + "' has no dispatcher"};
}

// nlohmann's exceptions' what() starts with "[json.exception.parse_error.101] ".
std::string parse_reason(const json::exception& e) {
  std::string_view w = e.what();
  if (const auto close = w.find("] "); !w.empty() && w.front() == '[' && close != std::string_view::npos)
    w.remove_prefix(close + 2);
  return std::string(w);
}

}  // namespace

std::string to_line(const json& j) { return j.dump(-1, ' ', false, json::error_handler_t::replace); }

std::string error_response(const std::string& message) { return error_line(json(), message); }

std::string handle_request_line(std::string_view line, ControlHandler& handler) {
  json id;  // null until the request says otherwise
  try {
    // JSON text has no NUL byte (not even inside a string); nlohmann's
    // iterator input stopped at one and took what came before.
    if (const std::size_t nul = line.find('\0'); nul != std::string_view::npos)
      return error_line(id, "malformed JSON: a NUL byte at position " + std::to_string(nul));
    // Duplicate keys: JSON leaves them to the reader and nlohmann keeps the
    // last, so {"cmd":"status","cmd":"pause"} paused. Refused, as in YAML.
    std::vector<std::set<std::string>> object_keys;
    std::string duplicate;
    const json::parser_callback_t note_keys = [&](int, json::parse_event_t event, json& parsed) {
      if (event == json::parse_event_t::object_start) object_keys.emplace_back();
      if (event == json::parse_event_t::object_end) object_keys.pop_back();
      if (event == json::parse_event_t::key && !object_keys.back().insert(parsed.get<std::string>()).second &&
          duplicate.empty())
        duplicate = parsed.get<std::string>();
      return true;
    };
    json request;
    try {
      request = json::parse(line.begin(), line.end(), note_keys);
      if (!duplicate.empty()) return error_line(id, "duplicate key " + printable(duplicate) + ": give each key once");
    } catch (const json::parse_error& e) {
      return error_line(id, "malformed JSON: " + parse_reason(e));
    } catch (const json::out_of_range& e) {  // a number beyond double, e.g. 1e999
      return error_line(id, "malformed JSON: " + parse_reason(e));
    }
    if (!request.is_object())
      return error_line(
          id, "a request must be a JSON object like {\"id\":1,\"cmd\":\"status\"}, got " + type_name(request));
    if (const auto it = request.find("id"); it != request.end()) {
      if (deeper_than(*it, kMaxJsonDepth))
        return error_line(id, "'id' is nested too deeply (more than " + std::to_string(kMaxJsonDepth) + " levels)");
      id = *it;
    }
    const auto cmd_it = request.find("cmd");
    if (cmd_it == request.end()) return error_line(id, "missing 'cmd' (the command name, e.g. \"status\")");
    if (!cmd_it->is_string()) return error_line(id, "'cmd' must be a string, got " + type_name(*cmd_it));
    const std::string& name = cmd_it->get_ref<const std::string&>();
    const auto c = std::find_if(kCommands.begin(), kCommands.end(), [&](const Command& k) { return k.name == name; });
    if (c == kCommands.end()) {
      if (name.size() > kMaxCommandNameBytes) return error_line(id, "unknown command " + printable(name));
      return error_line(id, "unknown command '" + name + "'");
    }
    for (const auto& [key, value] : request.items()) {
      if (key == "id" || key == "cmd") continue;
      if (!c->takes(key))
        return error_line(id, "unexpected argument " + printable(key) + " for command '" + name +
                                  "' (allowed: " + allowed_list(*c) + ")");
    }
    try {
      return ok_line(id, dispatch(*c, request, handler));
    } catch (const BadRequest& e) {
      return error_line(id, e.message);
    } catch (const ControlError& e) {
      return error_line(id, e.what());
    } catch (const std::exception& e) {
      return error_line(id, std::string("internal error: ") + e.what());
    } catch (...) {
      return error_line(id, "internal error: unknown exception");
    }
  } catch (const std::exception& e) {
    // Only allocation failures and the like get here; the connection lives on.
    return error_line(id, std::string("internal error: ") + e.what());
  }
}

bool is_valid_key_path(std::string_view key) {
  if (key.empty()) return false;
  const auto name_char = [](char c) {
    return (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9') || c == '_' || c == '-';
  };
  std::size_t i = 0;
  bool need_name = true;  // a key path starts with a name and has one after each '.'
  while (i < key.size()) {
    if (need_name) {
      const std::size_t start = i;
      while (i < key.size() && name_char(key[i])) ++i;
      if (i == start) return false;
      need_name = false;
    } else if (key[i] == '.') {
      ++i;
      need_name = true;
    } else if (key[i] == '[') {
      const std::size_t start = ++i;
      while (i < key.size() && key[i] >= '0' && key[i] <= '9') ++i;
      if (i == start || i >= key.size() || key[i] != ']') return false;
      ++i;
    } else {
      return false;
    }
  }
  return !need_name;
}

std::string set_override_text(const std::string& key, const json& value) { return key + "=" + to_line(value); }

}  // namespace tissue::control
