#include "app/trade_options.hpp"

#include <algorithm>
#include <cmath>
#include <functional>
#include <optional>
#include <set>
#include <sstream>
#include <stdexcept>

#include "app/trade_beam_theory.hpp"
#include "scene/scene_names.hpp"
#include "util/output_file.hpp"
#include "util/text.hpp"

namespace tissue::app {

namespace sc = tissue::scene;

namespace {

std::vector<std::string> split_list(const std::string& s) {
  std::vector<std::string> out;
  std::stringstream ss(s);
  std::string item;
  while (std::getline(ss, item, ',')) out.push_back(item);
  return out;
}

// The whole of `text` as a finite number > 0 (or an integer in [0, 30] for
// depths); anything else is the option's error, naming the value. std::stod
// alone took "20abc" as 20, "nan" as NaN and said only "stod" for ",".
double positive_number(const std::string& option, const std::string& text) {
  const std::optional<double> read = util::whole_number(text);
  if (!read) throw std::invalid_argument(option + ": '" + text + "' is not a number");
  const double v = *read;
  if (!(std::isfinite(v) && v > 0.0))
    throw std::invalid_argument(option + ": " + text + " must be a finite number > 0");
  return v;
}

int depth(const std::string& option, const std::string& text) {
  std::size_t used = 0;
  long v = -1;
  try {
    v = std::stol(text, &used);
  } catch (const std::exception&) {
    used = 0;
  }
  if (used == 0 || used != text.size()) throw std::invalid_argument(option + ": '" + text + "' is not an integer");
  if (v < 0 || v > 30) throw std::invalid_argument(option + ": " + text + " must be a depth in [0, 30]");
  return static_cast<int>(v);
}

// The value after the option being read (throws when there is none).
using NextValue = std::function<std::string()>;

// The mode flags and the options taking a name or a path. False: `a` is none of them.
bool read_mode_or_name(const std::string& a, const NextValue& value, TradeOptions& o) {
  if (a == "--table1")
    o.table1 = true;
  else if (a == "--sweep")
    o.sweep = true;
  else if (a == "--beam-theory")
    o.beam_theory = true;
  else if (a == "--quick")
    o.quick = true;
  else if (a == "--csv")
    o.csv_path = value();
  else if (a == "--svg")
    o.svg_path = value();
  else if (a == "--scene")
    o.sweep_scene = value();
  else if (a == "--scene-file")
    o.scene_file = value();
  else if (a == "--set")
    o.scene_overrides.push_back(value());
  else if (a == "--metric")
    o.metric = value();
  else
    return false;
  return true;
}

// The options taking numbers (or a list). False: `a` is none of them.
bool read_numbers(const std::string& a, const NextValue& value, TradeOptions& o) {
  if (a == "--th") {
    for (const auto& t : split_list(value())) o.th_Pa.push_back(positive_number("--th", t));
  } else if (a == "--depths") {
    for (const auto& t : split_list(value())) o.max_depths.push_back(depth("--depths", t));
  } else if (a == "--integrators") {
    for (auto& name : split_list(value())) o.integrators.push_back(std::move(name));  // repeats add, as the other lists
  } else if (a == "--dts") {
    for (const auto& t : split_list(value())) o.dts_s.push_back(positive_number("--dts", t));
  } else if (a == "--duration") {
    o.sweep_duration_s = positive_number("--duration", value());
  } else if (a == "--run-cap") {
    o.run_cap_s = positive_number("--run-cap", value());
  } else if (a == "--beam-depth") {
    o.beam_max_depth = depth("--beam-depth", value());
  } else {
    return false;
  }
  return true;
}

// The options taking one of a few words, checked here. False: `a` is none of them.
bool read_choice(const std::string& a, const NextValue& value, TradeOptions& o) {
  if (a == "--clock") {
    const std::string c = value();
    if (c != "wall" && c != "cpu") throw std::invalid_argument("--clock must be wall or cpu");
    o.cpu_clock = c == "cpu";
  } else if (a == "--preconditioner") {
    o.preconditioner = value();
    if (!sc::value_named(sc::kCgPreconditionerNames, o.preconditioner))
      throw std::invalid_argument("--preconditioner must be jacobi, two_level or auto");
  } else if (a == "--explicit-precision") {
    o.explicit_precision = value();
    if (!sc::value_named(sc::kExplicitPrecisionNames, o.explicit_precision))
      throw std::invalid_argument("--explicit-precision must be double or float");
  } else {
    return false;
  }
  return true;
}

// The options only the sweep reads: Table 1 and beam theory run their
// built-in scenes with --quick alone (--csv and --svg have their own message).
const std::set<std::string> kSweepOnly = {"--scene",
                                          "--scene-file",
                                          "--set",
                                          "--metric",
                                          "--th",
                                          "--depths",
                                          "--integrators",
                                          "--dts",
                                          "--duration",
                                          "--run-cap",
                                          "--clock",
                                          "--preconditioner",
                                          "--explicit-precision"};

// No mode flag: all three modes, but a scene file is for the sweep.
void default_modes(TradeOptions& o) {
  if (o.table1 || o.sweep || o.beam_theory) return;
  if (o.scene_file.empty())
    o.table1 = o.sweep = o.beam_theory = true;
  else
    o.sweep = true;
}

// A value given twice in a list (or across repeats of its option) ran its
// points twice: twice the time, duplicate rows in the CSV and points drawn
// over each other in the plot.
template <class T>
void no_repeats(const std::string& option, const std::vector<T>& values) {
  for (std::size_t i = 0; i < values.size(); ++i)
    for (std::size_t j = 0; j < i; ++j)
      if (values[j] == values[i]) {
        std::ostringstream text;
        text << values[i];
        throw std::invalid_argument(option + ": " + text.str() + " is given twice (each point of the sweep runs once)");
      }
}

// What no single option shows wrong: names out of their lists, options for
// a mode or a file that is not asked for (`given`: the options on the
// command line, in order), both files at one path.
void check_together(const TradeOptions& o, const std::vector<std::string>& given) {
  if (o.sweep_scene != "cantilever" && o.sweep_scene != "beam" && o.sweep_scene != "beam-r")
    throw std::invalid_argument("--scene must be cantilever, beam or beam-r");
  // Without --sweep these were silently ignored: `--table1 --scene-file
  // mine.yaml` ran Table 1 on the built-in cantilever, never opening the file.
  for (const std::string& option : given) {
    if (!o.sweep && kSweepOnly.count(option))
      throw std::invalid_argument(option +
                                  " is the sweep's option (Table 1 and beam theory do not read it): add --sweep");
    if (!o.beam_theory && option == "--beam-depth")
      throw std::invalid_argument("--beam-depth is the beam-theory table's option: add --beam-theory");
  }
  const auto is_given = [&](const char* option) {
    return std::find(given.begin(), given.end(), option) != given.end();
  };
  if (is_given("--scene") && is_given("--scene-file"))
    throw std::invalid_argument("--scene and --scene-file both name the sweep's scene: give one");
  if (!o.scene_overrides.empty() && o.scene_file.empty())
    throw std::invalid_argument("--set applies to --scene-file; the built-in scenes take none");
  if (!o.sweep && (!o.csv_path.empty() || !o.svg_path.empty()))
    throw std::invalid_argument("--csv and --svg are the sweep's files: add --sweep");
  if (!o.csv_path.empty() && !o.svg_path.empty() &&
      (o.csv_path == o.svg_path || util::same_file(o.csv_path, o.svg_path)))
    throw std::invalid_argument("--csv and --svg name the same file '" + o.csv_path +
                                "': the plot would replace the table");
  if (o.metric != "rms" && o.metric != "max" && o.metric != "tip" && o.metric != "path")
    throw std::invalid_argument("--metric must be rms, max, tip or path");
  if (o.beam_max_depth >= 0) check_beam_depth(o.beam_max_depth);
  no_repeats("--th", o.th_Pa);
  no_repeats("--depths", o.max_depths);
  no_repeats("--integrators", o.integrators);
  no_repeats("--dts", o.dts_s);
}

}  // namespace

TradeOptions parse_trade_options(const std::vector<std::string>& args) {
  TradeOptions o;
  std::vector<std::string> given;  // the options read, for check_together
  for (std::size_t i = 0; i < args.size(); ++i) {
    const std::string& a = args[i];
    const NextValue value = [&]() -> std::string {
      if (i + 1 >= args.size()) throw std::invalid_argument("missing value after " + args[i]);
      return args[++i];
    };
    if (a == "-h" || a == "--help") {
      o.help = true;
      return o;
    }
    if (!read_mode_or_name(a, value, o) && !read_numbers(a, value, o) && !read_choice(a, value, o))
      throw std::invalid_argument("unknown argument " + a);
    given.push_back(a);
  }
  default_modes(o);
  check_together(o, given);
  return o;
}

void print_trade_usage(const std::string& program, std::FILE* to) {
  std::fprintf(to, "usage: %s", program.c_str());
  std::fputs(
      " [--table1] [--sweep] [--beam-theory] [--quick]\n"
      "  sweep: [--csv FILE] [--svg FILE] [--scene cantilever|beam|beam-r] [--th 2,20,...]\n"
      "         [--scene-file FILE [--set key.path=value ...]]   (a scene of your own; defaults from it:\n"
      "          Th x 1/4, 1, 4, its max depth, its dt; uniform levels from its min depth)\n"
      "         [--depths 3,6] [--integrators implicit,explicit,projective] [--dts 0.001,0.005]\n"
      "         [--duration S] [--metric rms|max|tip|path] [--run-cap S] [--clock wall|cpu]\n"
      "         [--preconditioner jacobi|two_level|auto]   (default jacobi, as the README's tables;\n"
      "          a scene file: its own)\n"
      "         [--explicit-precision double|float]   (the explicit rung's arithmetic, default double;\n"
      "          a scene file: its own)\n"
      "  beam-theory: [--beam-depth D]   (uniform depths 0..D, each a scene the scene checks accept:\n"
      "          at most 16, 192 x 2^16 tetrahedra)\n"
      "no mode flag: all three modes (with --scene-file: the sweep); the sweep's options need the sweep,\n"
      "  --beam-depth the beam theory; --scene and --scene-file exclude each other\n"
      "--quick: shorter runs and fewer points everywhere (the defaults in brackets below)\n"
      "--scene: cantilever (the paper's, 5 N tip load), beam (PERFORMANCE.md's 0.4 m beam, 8x2x2 cubes),\n"
      "  beam-r (the same beam as 12x3x3 cubes, whose uniform depths 0, 3, 6, 9 are PERFORMANCE.md's R1..R4)\n"
      "defaults: --duration 0.5 s for the cantilever and a scene file, 1 s for the beams [0.2 / 0.5];\n"
      "  --metric rms; --run-cap 30 s of wall (or CPU) time per run [3]; --depths 3,6 [3];\n"
      "  --dts 0.001,0.005; --integrators all three; --beam-depth 6 [4]\n"
      "--csv / --svg are created before any run. Ctrl-C (or SIGTERM) during the sweep stops it after the\n"
      "step in progress and still prints its tables and writes its files for the runs done; Ctrl-C again kills.\n"
      "exit codes: 0 done, 2 bad option or scene, 3 every run of the sweep failed or was refused, 4 --csv/--svg not\n"
      "writable, 128+N sweep stopped by signal N\n",
      to);
}

}  // namespace tissue::app
