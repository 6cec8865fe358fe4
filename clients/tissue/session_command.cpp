#include "tissue/session_command.hpp"

#include <CLI/CLI.hpp>

#include <iostream>
#include <memory>
#include <string>

#include "record/session_tools.hpp"

namespace tissue::cli {

namespace {

constexpr int kExitBadFile = 1;  // same value as kExitDaemonError: "the thing you asked about is broken"

struct SessionOptions {
  std::string file;
  std::string xdmf_out;
  CLI::App* info = nullptr;
  CLI::App* repair = nullptr;
  CLI::App* xdmf = nullptr;
};

void print_counts(const char* label, const record::GroupCounts& c) {
  std::cout << label << c.haptic_rows << " haptic ticks, " << c.sim_rows << " sim samples, " << c.mesh_frames
            << " mesh frames, " << c.events << " events\n";
}

int run_session(const SessionOptions& o) {
  try {
    if (o.info->parsed()) {
      std::cout << record::format_session_info(record::read_session_info(o.file));
      return kExitOk;
    }
    if (o.repair->parsed()) {
      const record::RepairReport r = record::repair_session(o.file);
      for (const std::string& note : r.notes) std::cout << "note: " << note << "\n";
      if (r.repair_needed) {
        std::cout << "repaired " << o.file << ": ordinary HDF5 readers can open it now\n";
        print_counts("recovered: ", r.after.rows);
      } else {
        print_counts("contents: ", r.after.rows);
      }
      return kExitOk;
    }
    if (o.xdmf->parsed()) {
      const record::XdmfReport r = record::write_xdmf(o.file, o.xdmf_out);
      std::cout << "wrote " << r.out_path << ": " << r.frames << " mesh frames";
      if (r.skipped_empty > 0) std::cout << " (" << r.skipped_empty << " empty frames skipped)";
      std::cout << "\n";
      return kExitOk;
    }
  } catch (const record::RecordError& e) {
    std::cerr << "tissue session: " << e.what() << "\n";
    return kExitBadFile;
  }
  return kExitBadArguments;
}

}  // namespace

Subcommand add_session_command(CLI::App& parent) {
  auto options = std::make_shared<SessionOptions>();
  CLI::App* session = parent.add_subcommand("session", "Inspect, repair and export recorded session files (HDF5)");
  session->require_subcommand(1);
  options->info = session->add_subcommand("info", "Duration, row counts, scene, host, version, clean close or crash");
  options->info->add_option("file", options->file, "Session file (.h5)")->required();
  options->repair = session->add_subcommand(
      "repair",
      "Make a session left by a crash readable by ordinary HDF5 readers (h5clear -s --increment, in-library)");
  options->repair->add_option("file", options->file, "Session file (.h5)")->required();
  options->xdmf =
      session->add_subcommand("xdmf", "Write an XDMF sidecar so ParaView opens the mesh frames as a time series");
  options->xdmf->add_option("file", options->file, "Session file (.h5)")->required();
  options->xdmf->add_option("-o,--output", options->xdmf_out, "Sidecar path (default: FILE with .xdmf)");
  return Subcommand{session, [options] { return run_session(*options); }};
}

}  // namespace tissue::cli
