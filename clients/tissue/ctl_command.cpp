#include "tissue/ctl_command.hpp"

#include <sys/un.h>

#include <CLI/CLI.hpp>

#include <chrono>
#include <cmath>
#include <filesystem>
#include <iostream>
#include <memory>
#include <stdexcept>

#include "config/daemon_config.hpp"
#include "control/control_client.hpp"
#include "control/control_protocol.hpp"
#include "tissue/cli_checks.hpp"

namespace tissue::cli {

namespace {

struct CtlOptions {
  std::string socket_path = config::ControlSpec{}.unix_socket_path;
  int tcp_port = 0;
  double timeout_s = 10.0;
  std::string cmd;
  std::vector<std::string> words;
};

// A command-line value: JSON when it parses as JSON, the text itself otherwise
// (so `implicit` and `/tmp/x.yaml` need no quotes).
nlohmann::json word_value(const std::string& text) {
  nlohmann::json v = nlohmann::json::parse(text, nullptr, false);
  if (v.is_discarded()) return nlohmann::json(text);
  return v;
}

std::pair<std::string, std::string> split_pair(const std::string& word, const std::string& cmd) {
  const auto eq = word.find('=');
  if (eq == std::string::npos || eq == 0)
    throw std::invalid_argument("'" + cmd + "' takes key=value arguments, got '" + word + "'");
  return {word.substr(0, eq), word.substr(eq + 1)};
}

// Why `path` cannot name a Unix socket ("" when it can): a connection to it
// can only fail, and that failure read "(is tissued running?)", exit 3.
std::string socket_path_problem(const std::string& path) {
  constexpr std::size_t kMaxBytes = sizeof(sockaddr_un{}.sun_path) - 1;  // and its terminating NUL
  static_assert(kMaxBytes == 107, "the message and docs/control-protocol.md name 107");
  if (path.empty()) return "--socket: the path is empty";
  if (path.size() > kMaxBytes)
    return "--socket '" + path + "': " + std::to_string(path.size()) +
           " bytes, longer than a Unix socket path can be (107 bytes)";
  return {};
}

int run_ctl(const CtlOptions& o) {
  if (o.tcp_port == 0) {
    if (const std::string why = socket_path_problem(o.socket_path); !why.empty()) {
      std::cerr << "tissue ctl: " << why << "\n";
      return kExitBadArguments;
    }
  }
  nlohmann::json request;
  try {
    request = build_ctl_request(o.cmd, o.words);
  } catch (const std::invalid_argument& e) {
    std::cerr << "tissue ctl: " << e.what() << "\n";
    return kExitBadArguments;
  }
  if (!(o.timeout_s > 0.0) || !std::isfinite(o.timeout_s) || o.timeout_s > 3600.0) {
    std::cerr << "tissue ctl: --timeout must be in (0, 3600] seconds\n";
    return kExitBadArguments;
  }
  const auto timeout = std::chrono::milliseconds(static_cast<long long>(std::ceil(o.timeout_s * 1000.0)));
  try {
    control::ControlClient client =
        o.tcp_port != 0 ? control::ControlClient::connect_tcp(static_cast<std::uint16_t>(o.tcp_port), timeout)
                        : control::ControlClient::connect_unix(o.socket_path, timeout);
    const nlohmann::json response = client.request(request);
    if (response["ok"].get<bool>()) {
      std::cout << response.value("result", nlohmann::json::object())
                       .dump(2, ' ', false, nlohmann::json::error_handler_t::replace)
                << "\n";
      return kExitOk;
    }
    const nlohmann::json error = response.value("error", nlohmann::json("(no error message)"));
    std::cerr << "tissue ctl: " << o.cmd << ": "
              << (error.is_string() ? error.get<std::string>() : control::to_line(error)) << "\n";
    return kExitDaemonError;
  } catch (const control::ControlClientError& e) {
    std::cerr << "tissue ctl: " << e.what();
    if (e.kind() == control::ControlClientError::Kind::kConnect) std::cerr << " (is tissued running?)";
    std::cerr << "\n";
    // A garbled answer is the daemon's fault, not the user's: report it as a
    // daemon error. Everything else means there is no usable connection.
    return e.kind() == control::ControlClientError::Kind::kProtocol ? kExitDaemonError : kExitCannotConnect;
  }
}

}  // namespace

nlohmann::json build_ctl_request(const std::string& cmd, const std::vector<std::string>& words) {
  nlohmann::json request = nlohmann::json::object();
  request["cmd"] = cmd;
  if (cmd.empty()) throw std::invalid_argument("the command name is empty");
  std::size_t next = 0;
  if (cmd == "load_scene") {
    if (words.empty()) throw std::invalid_argument("'load_scene' needs the scene file: tissue ctl load_scene PATH");
    if (words[0].empty()) throw std::invalid_argument("'load_scene': the scene path is empty");
    // The daemon has another working directory: send what the user meant.
    std::error_code ec;
    const auto absolute = std::filesystem::absolute(words[0], ec);
    request["path"] = ec ? words[0] : absolute.lexically_normal().string();
    next = 1;
  } else if (cmd == "set") {
    if (words.empty())
      throw std::invalid_argument("'set' needs a key and a value: tissue ctl set KEY VALUE (or KEY=VALUE)");
    if (words.size() == 1 || (words[0].find('=') != std::string::npos && words[0].find('=') > 0)) {
      const auto [key, value] = split_pair(words[0], cmd);
      request["key"] = key;
      request["value"] = word_value(value);
      next = 1;
    } else {
      request["key"] = words[0];
      request["value"] = word_value(words[1]);
      next = 2;
    }
    if (!control::is_valid_key_path(request["key"].get<std::string>()))
      throw std::invalid_argument("'set': not a key path: '" + request["key"].get<std::string>() +
                                  "' (e.g. material.youngs_modulus_Pa)");
  }
  for (; next < words.size(); ++next) {
    const auto [key, value] = split_pair(words[next], cmd);
    if (key == "cmd" || key == "id") throw std::invalid_argument("'" + key + "' cannot be given as an argument");
    if (request.contains(key)) throw std::invalid_argument("argument '" + key + "' given twice");
    request[key] = word_value(value);
  }
  return request;
}

Subcommand add_ctl_command(CLI::App& parent) {
  auto options = std::make_shared<CtlOptions>();
  CLI::App* app = parent.add_subcommand("ctl", "Send one command to a running tissued and print the result");
  app->footer(
      "Usage: tissue ctl [--socket PATH | --tcp PORT] [--timeout S] CMD [ARGS...]\n"
      "The options go before CMD: everything after it is CMD's arguments, verbatim.\n"
      "Commands: status, pause, resume, reset, load_scene PATH, set KEY VALUE, shutdown,\n"
      "          record_start [name=FILE.h5], record_stop, export_x3d [name=FILE.x3d].\n"
      "Exit codes: 0 ok, 1 the daemon answered an error, 2 bad arguments, 3 cannot connect.");
  auto* socket_opt =
      app->add_option("--socket", options->socket_path, "Unix socket of the daemon")->capture_default_str();
  app->add_option("--tcp", options->tcp_port, "talk to 127.0.0.1:PORT instead of the Unix socket")
      ->transform(decimal_integer())
      ->check(CLI::Range(1, 65535))
      ->excludes(socket_opt);
  app->add_option("--timeout", options->timeout_s, "seconds to wait for the daemon")->capture_default_str();
  app->add_option("cmd", options->cmd, "command: status, pause, resume, reset, load_scene, set, shutdown, ...")
      ->required();
  // Everything after the command name is its arguments, verbatim: "-9.81"
  // is not an option and "[0,0,-1]" is not split into three (CLI11 would do
  // both to an ordinary positional list).
  app->prefix_command(true);
  return Subcommand{app, [options, app] {
                      options->words = app->remaining();
                      return run_ctl(*options);
                    }};
}

}  // namespace tissue::cli
