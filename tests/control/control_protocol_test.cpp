#include "control/control_protocol.hpp"

#include <gtest/gtest.h>

#include <string>

#include "control/fake_handler.hpp"
#include "scene/scene_yaml.hpp"

namespace tissue::control {
namespace {

using nlohmann::json;
using testing::FakeHandler;

json handle(const std::string& line, FakeHandler& h) {
  const std::string out = handle_request_line(line, h);
  EXPECT_EQ(out.find('\n'), std::string::npos) << "a response is one line";
  return json::parse(out);
}

// An error response with the given id whose message contains `part`.
void expect_error(const json& r, const json& id, const std::string& part) {
  EXPECT_EQ(r.at("ok"), false) << r;
  EXPECT_EQ(r.at("id"), id) << r;
  EXPECT_FALSE(r.contains("result")) << r;
  ASSERT_TRUE(r.at("error").is_string()) << r;
  EXPECT_NE(r.at("error").get<std::string>().find(part), std::string::npos) << r;
}

TEST(ControlProtocol, StatusRoundTripEchoesAnyId) {
  FakeHandler h;
  for (const json& id : {json(7), json("abc"), json(nullptr), json({{"n", 1}}), json::array({1, 2})}) {
    const json expected = h.status_result();
    const json r = handle(json{{"id", id}, {"cmd", "status"}}.dump(), h);
    EXPECT_EQ(r.at("ok"), true) << r;
    EXPECT_EQ(r.at("id"), id);
    EXPECT_EQ(r.at("result"), expected);
  }
  // No id: answered with id null.
  EXPECT_EQ(handle(R"({"cmd":"status"})", h).at("id"), json(nullptr));
  // Field order as documented: id, ok, result.
  EXPECT_EQ(handle_request_line(R"({"id":1,"cmd":"pause"})", h), R"({"id":1,"ok":true,"result":{"paused":true}})");
}

// Numeric ids as docs/control-protocol.md says: every integer below 2^64
// (and down to -2^63) exactly, larger ones and fractions as the nearest double.
TEST(ControlProtocol, NumericIdsComeBackAsDocumented) {
  FakeHandler h;
  const auto id_text = [&](const std::string& id) {
    const std::string out = handle_request_line(R"({"id":)" + id + R"(,"cmd":"pause"})", h);
    const std::size_t start = out.find(':') + 1;
    return out.substr(start, out.find(",\"ok\"") - start);
  };
  EXPECT_EQ(id_text("18446744073709551615"), "18446744073709551615");    // 2^64 - 1
  EXPECT_EQ(id_text("-9223372036854775808"), "-9223372036854775808");    // -2^63
  EXPECT_EQ(id_text("18446744073709551616"), "1.8446744073709552e+19");  // 2^64: a double
  EXPECT_EQ(id_text("1.50"), "1.5");
}

// A key given twice is refused, at any depth, before anything runs: nlohmann
// kept the last, so {"cmd":"status","cmd":"pause"} paused. A NUL byte is not
// JSON (it ended the parse early and what came before was taken).
TEST(ControlProtocol, DuplicateKeysAndNulBytesAreRefusedAndNothingRuns) {
  FakeHandler h;
  expect_error(handle(R"({"id":1,"cmd":"status","cmd":"pause"})", h), nullptr, "duplicate key 'cmd'");
  expect_error(handle(R"({"id":2,"id":3,"cmd":"pause"})", h), nullptr, "duplicate key 'id'");
  expect_error(handle(R"({"id":4,"cmd":"set","key":"name","value":{"a":1,"a":2}})", h), nullptr, "duplicate key 'a'");
  const std::string nul(1, '\0');
  expect_error(handle(R"({"id":5,"cmd":"pause"})" + nul, h), nullptr, "malformed JSON: a NUL byte at position 22");
  expect_error(handle(R"({"id":6,"cmd":"pa)" + nul + R"(use"})", h), nullptr, "a NUL byte at position 17");
  EXPECT_TRUE(h.calls().empty());
  // The same key in two different objects is fine.
  EXPECT_EQ(handle(R"({"id":{"a":1},"cmd":"set","key":"name","value":{"a":2}})", h).at("ok"), true);
}

// Duplicates are per object: a key of a nested object (here inside "id" and
// "value") may also be a key of the object around it.
TEST(ControlProtocol, AKeyOfANestedObjectMayRecurInTheObjectAroundIt) {
  FakeHandler h;
  EXPECT_EQ(handle(R"({"id":{"cmd":"x"},"cmd":"status"})", h).at("ok"), true);
  EXPECT_EQ(handle(R"({"id":1,"cmd":"set","value":{"key":1,"value":2},"key":"name"})", h).at("ok"), true);
  EXPECT_EQ(h.call_count(), 2u);
}

TEST(ControlProtocol, EveryCommandReachesTheHandlerWithItsArguments) {
  FakeHandler h;
  EXPECT_EQ(handle(R"({"id":1,"cmd":"pause"})", h).at("ok"), true);
  EXPECT_EQ(handle(R"({"id":2,"cmd":"resume"})", h).at("ok"), true);
  EXPECT_EQ(handle(R"({"id":3,"cmd":"reset"})", h).at("result"), json({{"sim_time_s", 0.0}}));
  EXPECT_EQ(handle(R"({"id":4,"cmd":"load_scene","path":"/etc/tissued/scenes/beam.yaml"})", h).at("result"),
            json({{"scene", "/etc/tissued/scenes/beam.yaml"}}));
  EXPECT_EQ(handle(R"({"id":5,"cmd":"set","key":"material.youngs_modulus_Pa","value":8e4})", h).at("ok"), true);
  EXPECT_EQ(handle(R"({"id":6,"cmd":"set","key":"loads[0].total_force_N","value":[0,0,-2]})", h).at("ok"), true);
  // A handler returning null answers an empty result object.
  EXPECT_EQ(handle(R"({"id":7,"cmd":"shutdown"})", h).at("result"), json::object());

  const auto calls = h.calls();
  ASSERT_EQ(calls.size(), 7u);
  EXPECT_EQ(calls[0].cmd, "pause");
  EXPECT_EQ(calls[1].cmd, "resume");
  EXPECT_EQ(calls[2].cmd, "reset");
  EXPECT_EQ(calls[3].cmd, "load_scene");
  EXPECT_EQ(calls[3].args.at("path"), "/etc/tissued/scenes/beam.yaml");
  EXPECT_EQ(calls[4].cmd, "set");
  EXPECT_EQ(calls[4].args.at("key"), "material.youngs_modulus_Pa");
  EXPECT_DOUBLE_EQ(calls[4].args.at("value").get<double>(), 8e4);
  EXPECT_EQ(calls[5].args.at("value"), json::array({0, 0, -2}));
  EXPECT_EQ(calls[6].cmd, "shutdown");
}

TEST(ControlProtocol, MalformedRequestsAreAnsweredNotThrown) {
  FakeHandler h;
  expect_error(handle("{\"id\":1,\"cmd\":", h), nullptr, "malformed JSON");
  expect_error(handle("not json at all", h), nullptr, "malformed JSON");
  expect_error(handle("{\"cmd\":\"status\"} trailing", h), nullptr, "malformed JSON");
  // A number beyond double is the request's fault, not an internal error.
  expect_error(handle("{\"id\":1,\"cmd\":\"set\",\"key\":\"a\",\"value\":1e999}", h), nullptr,
               "malformed JSON: number overflow parsing '1e999'");
  expect_error(handle("{\"id\":1e999,\"cmd\":\"status\"}", h), nullptr, "malformed JSON: number overflow");
  expect_error(handle("[1,2,3]", h), nullptr, "must be a JSON object");
  expect_error(handle("\"status\"", h), nullptr, "must be a JSON object");
  expect_error(handle(R"({"id":3})", h), 3, "missing 'cmd'");
  expect_error(handle(R"({"id":4,"cmd":5})", h), 4, "'cmd' must be a string, got a number");
  expect_error(handle(std::string("{\"cmd\":\"\xff\xfe\"}"), h), nullptr, "malformed JSON");
  EXPECT_EQ(h.call_count(), 0u);
}

TEST(ControlProtocol, RecordCommandsTakeAnOptionalName) {
  FakeHandler h;
  EXPECT_EQ(handle(R"({"id":1,"cmd":"record_start","name":"s1.h5"})", h).at("result"), json({{"file", "s1.h5"}}));
  EXPECT_EQ(handle(R"({"id":2,"cmd":"record_start"})", h).at("result"), json({{"file", ""}}));
  EXPECT_TRUE(handle(R"({"id":3,"cmd":"record_stop"})", h).at("ok").get<bool>());
  expect_error(handle(R"({"id":4,"cmd":"record_start","name":7})", h), 4, "must be a string, got a number");
  expect_error(handle(R"({"id":5,"cmd":"record_start","name":""})", h), 5, "must not be empty");
  expect_error(handle(json{{"id", 6}, {"cmd", "record_start"}, {"name", std::string(300, 'n')}}.dump(), h), 6,
               "too long");
  const auto calls = h.calls();
  ASSERT_EQ(calls.size(), 3u);
  EXPECT_EQ(calls[0].cmd, "record_start");
  EXPECT_EQ(calls[2].cmd, "record_stop");
  EXPECT_EQ(handle(R"({"id":7,"cmd":"export_x3d","name":"a.x3d"})", h).at("result"), json({{"file", "a.x3d"}}));
  EXPECT_EQ(handle(R"({"id":8,"cmd":"export_x3d"})", h).at("result"), json({{"file", ""}}));
}

TEST(ControlProtocol, UnknownAndReservedCommands) {
  FakeHandler h;
  EXPECT_EQ(handle_request_line(R"({"id":9,"cmd":"x"})", h), R"({"id":9,"ok":false,"error":"unknown command 'x'"})");
  for (const char* unknown : {"export_vrml", "record"})
    expect_error(handle(json{{"id", 1}, {"cmd", unknown}}.dump(), h), 1,
                 std::string("unknown command '") + unknown + "'");
  // A huge name is cut in the message.
  const json r = handle(json{{"cmd", std::string(5000, 'q')}}.dump(), h);
  expect_error(r, nullptr, "unknown command 'qqq");
  EXPECT_LT(r.at("error").get<std::string>().size(), 200u);
  EXPECT_EQ(h.call_count(), 0u);
}

TEST(ControlProtocol, ArgumentsAreCheckedBeforeTheHandler) {
  FakeHandler h;
  expect_error(handle(R"({"id":1,"cmd":"load_scene"})", h), 1, "command 'load_scene' needs argument 'path'");
  expect_error(handle(R"({"id":2,"cmd":"load_scene","path":5})", h), 2, "must be a string, got a number");
  expect_error(handle(R"({"id":3,"cmd":"load_scene","path":""})", h), 3, "must not be empty");
  expect_error(handle(json{{"id", 3}, {"cmd", "load_scene"}, {"path", std::string(5000, 'p')}}.dump(), h), 3,
               "too long");
  expect_error(handle(R"({"id":4,"cmd":"set","key":"a.b"})", h), 4, "needs argument 'value'");
  expect_error(handle(R"({"id":5,"cmd":"set","value":1})", h), 5, "needs argument 'key'");
  expect_error(handle(R"({"id":6,"cmd":"set","key":"a..b","value":1})", h), 6, "not a key path");
  expect_error(handle(R"({"id":7,"cmd":"set","key":["a"],"value":1})", h), 7, "must be a string, got an array");
  expect_error(handle(R"({"id":8,"cmd":"status","verbose":true})", h), 8,
               "unexpected argument 'verbose' for command 'status' (allowed: id, cmd)");
  expect_error(handle(R"({"id":9,"cmd":"set","key":"a","value":1,"path":"x"})", h), 9,
               "(allowed: id, cmd, key, value)");
  expect_error(handle(R"({"id":10,"cmd":"set","key":"a","value":[[[[[[[[[[[[[[[[[[[[1]]]]]]]]]]]]]]]]]]]]})", h), 10,
               "nested too deeply");
  EXPECT_EQ(h.call_count(), 0u);
  // null is a value like any other (it switches some daemon settings off).
  EXPECT_EQ(handle(R"({"id":11,"cmd":"set","key":"control.unix_socket_path","value":null})", h).at("ok"), true);
  EXPECT_EQ(h.call_count(), 1u);
}

// docs/control-protocol.md gives the limits as "at most": a value of exactly
// the limit is taken, one byte more is refused before the handler.
TEST(ControlProtocol, ArgumentsOfExactlyTheDocumentedLengthAreTakenAndOneByteMoreIsRefused) {
  FakeHandler h;
  const auto request = [](const char* cmd, const char* arg, const std::string& text) {
    json r{{"id", 1}, {"cmd", cmd}, {arg, text}};
    if (std::string(cmd) == "set") r["value"] = 1;
    return r.dump();
  };
  struct Limit {
    const char* cmd;
    const char* arg;
    std::size_t bytes;
  };
  for (const Limit& l :
       {Limit{"load_scene", "path", kMaxPathBytes}, Limit{"set", "key", kMaxKeyPathBytes},
        Limit{"record_start", "name", kMaxFileNameBytes}, Limit{"export_x3d", "name", kMaxFileNameBytes}}) {
    const std::size_t before = h.call_count();
    EXPECT_EQ(handle(request(l.cmd, l.arg, std::string(l.bytes, 'k')), h).at("ok"), true) << l.cmd;
    EXPECT_EQ(h.call_count(), before + 1) << l.cmd;
    expect_error(handle(request(l.cmd, l.arg, std::string(l.bytes + 1, 'k')), h), 1,
                 "is too long (" + std::to_string(l.bytes + 1) + " bytes, at most " + std::to_string(l.bytes) + ")");
    EXPECT_EQ(h.call_count(), before + 1) << l.cmd;
  }
}

// A NUL escaped inside a JSON string (\u0000) is valid JSON, but a path or
// name holding one would be cut there by every C API the daemon hands it to
// (a different file than the one asked for): refused naming the argument.
TEST(ControlProtocol, AnEscapedNulInsideAStringArgumentIsRefusedNamingTheArgument) {
  FakeHandler h;
  expect_error(handle(R"({"id":1,"cmd":"load_scene","path":"/tmp/a.yaml\u0000.txt"})", h), 1,
               "argument 'path' of 'load_scene' must not contain a NUL character");
  expect_error(handle(R"({"id":2,"cmd":"record_start","name":"s\u0000.h5"})", h), 2,
               "argument 'name' of 'record_start' must not contain a NUL character");
  EXPECT_EQ(h.call_count(), 0u);
}

// "id: any JSON value (nesting at most 16 levels)": 16 levels echo, 17 are refused.
TEST(ControlProtocol, AnIdNestedSixteenLevelsIsEchoedAndSeventeenAreRefused) {
  FakeHandler h;
  const auto nested = [](int levels) { return std::string(levels, '[') + std::string(levels, ']'); };
  const json r = handle("{\"id\":" + nested(16) + ",\"cmd\":\"pause\"}", h);
  EXPECT_EQ(r.at("ok"), true) << r;
  EXPECT_EQ(r.at("id"), json::parse(nested(16)));
  expect_error(handle("{\"id\":" + nested(17) + ",\"cmd\":\"pause\"}", h), nullptr,
               "'id' is nested too deeply (more than 16 levels)");
  EXPECT_EQ(h.call_count(), 1u);
}

TEST(ControlProtocol, HandlerFailuresBecomeErrorResponses) {
  FakeHandler h;
  h.fail_with(FakeHandler::Failure::kControlError, "no scene loaded: load one with load_scene");
  EXPECT_EQ(handle_request_line(R"({"id":1,"cmd":"reset"})", h),
            R"({"id":1,"ok":false,"error":"no scene loaded: load one with load_scene"})");
  h.fail_with(FakeHandler::Failure::kOtherException, "boom");
  expect_error(handle(R"({"id":2,"cmd":"status"})", h), 2, "internal error: boom");
  EXPECT_EQ(h.call_count(), 2u);
}

TEST(ControlProtocol, DeepNestingNeitherCrashesNorEchoes) {
  FakeHandler h;
  const std::string deep_id = "{\"id\":" + std::string(100000, '[') + std::string(100000, ']') + ",\"cmd\":\"status\"}";
  expect_error(handle(deep_id, h), nullptr, "'id' is nested too deeply");
  const std::string deep = std::string(200000, '[') + std::string(200000, ']');
  expect_error(handle(deep, h), nullptr, "must be a JSON object");
  EXPECT_EQ(h.call_count(), 0u);
}

TEST(ControlProtocol, HelpersForTheService) {
  EXPECT_TRUE(is_valid_key_path("material.youngs_modulus_Pa"));
  EXPECT_TRUE(is_valid_key_path("loads[0].total_force_N[2]"));
  EXPECT_TRUE(is_valid_key_path("haptics.rate_hz"));
  for (const char* bad :
       {"", ".a", "a.", "a..b", "a[", "a[x]", "[0]", "a b", "a]", "a[0]b", "a=b", "a[0", "a[0x", "a[1}.b"})
    EXPECT_FALSE(is_valid_key_path(bad)) << bad;
  EXPECT_EQ(set_override_text("material.youngs_modulus_Pa", 80000.0), "material.youngs_modulus_Pa=80000.0");
  EXPECT_EQ(set_override_text("integrator.kind", "implicit"), "integrator.kind=\"implicit\"");
  EXPECT_EQ(set_override_text("gravity_m_per_s2", json::array({0, 0, -9.81})), "gravity_m_per_s2=[0,0,-9.81]");
  const json e = json::parse(error_response("request line too long"));
  EXPECT_EQ(e, json({{"id", nullptr}, {"ok", false}, {"error", "request line too long"}}));
  // Invalid UTF-8 from a handler is replaced, not thrown.
  EXPECT_NO_THROW(to_line(json(std::string("bad \xff byte"))));
}

TEST(ControlProtocol, SetOverrideTextIsReadBackByTheSceneLoader) {
  const std::string scene = std::string(TISSUE_SOURCE_DIR) + "/config/scenes/cantilever.yaml";
  const scene::Scene s = scene::load_scene_file_with_overrides(
      scene, {set_override_text("material.youngs_modulus_Pa", 8e4), set_override_text("integrator.kind", "explicit"),
              set_override_text("gravity_m_per_s2", json::array({0, 0, -9.81}))});
  EXPECT_DOUBLE_EQ(s.material.youngs_modulus_Pa, 8e4);
  EXPECT_EQ(s.integrator.kind, scene::IntegratorKind::kExplicit);
  EXPECT_DOUBLE_EQ(s.gravity_m_per_s2[2], -9.81);
  // A JSON string stays a string: "8e4" is not a number, as in the file.
  EXPECT_THROW(scene::load_scene_file_with_overrides(scene, {set_override_text("material.youngs_modulus_Pa", "8e4")}),
               scene::SceneError);
}

}  // namespace
}  // namespace tissue::control
