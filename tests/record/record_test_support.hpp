// Shared by the record suites: scratch directories, deterministic session
// content (so a reader can check every row without keeping what was
// written), HDF5 C-API readers, and running the `tissue` CLI and the helper.
#pragma once

#include <hdf5.h>

#include <array>
#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include "record/record_types.hpp"
#include "support/process_support.hpp"

namespace tissue::record::testing {

using tissue::testing::quote;
using tissue::testing::run;
using tissue::testing::RunResult;
using tissue::testing::slurp;
using tissue::testing::TempDir;

// Row i of a deterministic session (time_s = i ms; device_fresh on every
// fourth row, from row 1).
HapticRow haptic_row(std::uint64_t i);
SimRow sim_row(std::uint64_t i);
Event event_row(std::uint64_t i);

// Frame f: a strip of quads whose size depends on f; coordinates are exact
// in float32 so stored frames compare equal.
struct TestFrame {
  double time_s = 0.0;
  std::vector<std::array<double, 3>> vertices_m;
  std::vector<std::array<std::uint32_t, 3>> triangles;
  std::vector<std::uint8_t> vertex_level;
  std::vector<float> triangle_strain_energy_J_per_m3;  // one per triangle, distinct, exact in float32
  MeshFrameView view() const { return {time_s, vertices_m, triangles, vertex_level, triangle_strain_energy_J_per_m3}; }
};
TestFrame test_frame(std::uint64_t f);

// Exact equality of every field (rows read back must be what was written).
bool same_row(const HapticRow& a, const HapticRow& b);
bool same_row(const SimRow& a, const SimRow& b);

// A closed session written with SessionWriter: haptic_row(0 .. haptic-1),
// sim_row(0 .. sim-1), test_frame(0 .. frames-1) (without their strain when
// `strain` is false: stored as NaN, "not computed"), event_row(0 .. events-1).
struct TestSession {
  std::uint64_t haptic = 1500, sim = 40, frames = 5, events = 1;
  bool strain = true;
  std::string scene_name = "probe";
};
// Returns `path`.
std::string write_test_session(const std::string& path, const TestSession& content = {});

void write_bytes(const std::string& path, const std::string& bytes);

// A session whose writer died after a flush (the superblock still says "open
// for SWMR writing"): haptic_row(0..haptic_rows) and test_frame(0..frames),
// scene "crash", written by a child process that exits without closing.
void write_crashed_session(const std::string& path, std::uint64_t haptic_rows, std::uint64_t frames);

// Files every session reader and tool must refuse with a clear error naming
// the file: empty, text, random bytes, an HDF5 signature then noise, a good
// session truncated at several points (inside the signature, the superblock,
// the metadata and the data), an HDF5 file that is not a session, a missing
// file, a directory and a FIFO. Written into `dir`.
std::vector<std::string> bad_session_files(const TempDir& dir);

// Runs `call` (rethrowing what it throws) and says whether it opened the
// FIFO `fifo` for reading. A plain open of a FIFO blocks until a writer
// comes, so a tool that opens one hangs for good; here a watcher opens the
// FIFO for writing (without blocking) whenever a reader has it open, which
// lets such an open return: the call always ends, and the test fails
// instead of hanging.
bool opens_fifo_for_reading(const std::string& fifo, const std::function<void()>& call);

// Whole dataset, flattened, through the C API. `swmr` opens with
// H5F_ACC_SWMR_READ. Fails the current test (and returns empty) on error.
std::vector<double> read_f64(hid_t file, const char* path);
std::vector<float> read_f32(hid_t file, const char* path);
std::vector<std::uint64_t> read_u64(hid_t file, const char* path);
std::vector<std::int64_t> read_i64(hid_t file, const char* path);
std::vector<std::int32_t> read_i32(hid_t file, const char* path);
std::vector<std::uint8_t> read_u8(hid_t file, const char* path);
std::vector<std::string> read_messages(hid_t file, const char* path);
// /events/message of the session at `path`; empty when it cannot be opened.
std::vector<std::string> event_messages(const std::string& path);
// A string attribute of a closed file's root ("" when it cannot be read).
std::string root_string_attribute(const std::string& path, const char* name);

// Checks every row of a session against the generators: haptic rows
// [0, haptic), sim rows [0, sim), frames [0, frames), events [0, events).
// Adds gtest failures; returns the number of mismatching rows.
int expect_session_content(hid_t file, std::uint64_t haptic, std::uint64_t sim, std::uint64_t frames,
                           std::uint64_t events);

// Opens a closed session read-write (latest format), to damage it or make
// an older version of it. Returns a negative id on failure.
hid_t open_for_edit(const std::string& path);
// Turns a closed session into what the version-1 writer made: no
// /mesh/triangle_strain_energy_J_per_m3, no /haptic/device_fresh,
// format_version 1. Fails the test on error.
void make_version_1(const std::string& path);
// The same for the version-2 writer: no /haptic/device_fresh, format_version 2.
void make_version_2(const std::string& path);
// Overwrites element [row] (1-D) or [row][column] (2-D) of a dataset of a
// closed session with *value, of HDF5 memory type `mem_type`.
void overwrite_element(const std::string& path, const char* dataset, std::uint64_t row, std::uint64_t column,
                       hid_t mem_type, const void* value);
// Overwrites row `row` of a 1-D float32 / float64 dataset of a closed session.
void overwrite_f32(const std::string& path, const char* dataset, std::uint64_t row, float value);
void overwrite_f64(const std::string& path, const char* dataset, std::uint64_t row, double value);
// The same for the element (row, column) of an N x 3 float64 dataset.
void overwrite_f64_at(const std::string& path, const char* dataset, std::uint64_t row, std::uint64_t column,
                      double value);

// Runs a shell command line with stdout/stderr captured into `scratch`.

// Whether Debian's python (with h5py) is usable for the cross-checks.
bool have_system_h5py();

}  // namespace tissue::record::testing
