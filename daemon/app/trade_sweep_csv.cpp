#include "app/trade_sweep_csv.hpp"

#include <cmath>
#include <sstream>
#include <string>

#include "app/trade_format.hpp"

namespace tissue::app {

std::string csv_num(double v) { return std::isfinite(v) ? format_number("%.6g", v) : ""; }

std::string csv_quote(const std::string& s) {
  std::string out = "\"";
  for (char c : s) out += c == '"' ? std::string("\"\"") : std::string(1, c);
  return out + "\"";
}

namespace {

const char* const kCsvHeader =
    "scene,integrator,dt_s,max_depth,mode,level,th_Pa,status,message,steps,sim_s,wall_s,cpu_s,"
    "cost_wall_per_sim,cost_cpu_per_sim,"
    "nodes_end,tets_end,springs_end,peak_nodes,peak_tets,splits,merges,tip_uz_m,tip_err_rel,rms_err_rel,"
    "max_err_rel,unlocated,mean_solver_iterations,max_substeps,last_mesh_change_s,deepest_level,tets_at_deepest,"
    "unconverged_steps,tip_path_err_rel,path_truth\n";

// The cap reads the cost's clock (--clock): say which.
std::string capped_message(const RunStats& st) {
  return std::string("stopped by the per-run cap on ") + (st.cost_uses_cpu ? "thread CPU" : "wall") + " time";
}

void write_row(std::ostream& f, const std::string& scene, const SweepPoint& p,
               const std::map<int, std::string>& truth) {
  f << csv_quote(scene) << ',' << p.integrator << ',' << p.dt_s << ',' << p.max_depth << ','
    << (p.adaptive ? "adaptive" : "uniform") << ',' << (p.adaptive ? std::string() : std::to_string(p.level)) << ','
    << csv_num(p.th_Pa) << ',' << p.status() << ','
    << csv_quote(p.st.ok ? (p.st.capped ? capped_message(p.st) : "") : p.st.error) << ',' << p.st.steps << ','
    << csv_num(p.st.sim_s) << ',' << csv_num(p.st.wall_s) << ',' << csv_num(p.st.cpu_s) << ','
    << csv_num(p.st.wall_cost()) << ',' << csv_num(p.st.cpu_cost()) << ',' << p.nodes << ',' << p.tets << ','
    << p.springs << ',' << p.peak_nodes << ',' << p.peak_tets << ',' << p.splits << ',' << p.merges << ','
    << (p.captured ? csv_num(p.tip[2]) : "") << ',' << csv_num(p.tip_err) << ',' << csv_num(p.rms_err) << ','
    << csv_num(p.max_err) << ',' << p.unlocated << ',' << csv_num(p.st.mean_iterations()) << ',' << p.st.max_substeps
    << ',' << csv_num(p.st.last_adapt_s) << ',' << p.deepest << ',' << p.tets_at_deepest << ','
    << p.st.unconverged_steps << ',' << csv_num(p.path_err) << ','
    << csv_quote(truth.count(p.max_depth) ? truth.at(p.max_depth) : "") << '\n';
}

}  // namespace

std::string csv_text(const std::string& scene, const std::vector<SweepPoint>& points,
                     const std::map<int, std::string>& truth) {
  std::ostringstream f;
  f << kCsvHeader;
  for (const auto& p : points) write_row(f, scene, p, truth);
  return f.str();
}

}  // namespace tissue::app
