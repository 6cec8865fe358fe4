#include "record_test_support.hpp"

#include <fcntl.h>
#include <gtest/gtest.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <random>
#include <sstream>
#include <stdexcept>
#include <thread>

#include "record/h5_util.hpp"
#include "record/session_layout.hpp"
#include "record/session_writer.hpp"

namespace tissue::record::testing {

HapticRow haptic_row(std::uint64_t i) {
  HapticRow r;
  const double x = static_cast<double>(i);
  r.time_s = x * 1e-3;
  r.device_position_m = {0.01 * std::sin(x * 1e-2), 0.01 * std::cos(x * 1e-2), -1e-6 * x};
  r.proxy_position_m = {r.device_position_m[0], r.device_position_m[1], std::max(0.0, r.device_position_m[2])};
  r.force_N = {0.5 * std::sin(x), -0.25 * x * 1e-3, 3.0};
  r.contact = static_cast<std::uint8_t>(i % 3 == 0);
  r.model_version = i / 7 + (std::uint64_t{1} << 40);
  r.device_fresh = static_cast<std::uint8_t>(i % 4 == 1);  // a 250 Hz device's cadence
  return r;
}

SimRow sim_row(std::uint64_t i) {
  SimRow r;
  const double x = static_cast<double>(i);
  r.time_s = x * 0.02;
  r.sim_time_s = x * 0.019;
  r.real_time_factor = 0.95 + 1e-3 * static_cast<double>(i % 50);
  r.step_ms = 0.1 + 1e-4 * x;
  r.nodes = 1000 + i;
  r.tets = 4000 + 3 * i;
  r.springs = 6000 + 5 * i;
  r.refines = static_cast<std::int64_t>(i / 2);
  r.merges = -static_cast<std::int64_t>(i / 5);  // not physical; proves the sign survives
  r.kinetic_J = 1e-3 * x;
  r.elastic_J = 2e-3 * x;
  return r;
}

Event event_row(std::uint64_t i) {
  // Every third message is longer than the field: it must come back cut to 255 bytes.
  std::string text = "event " + std::to_string(i) + " \xc3\xa9";  // with a UTF-8 character
  if (i % 3 == 2) text += std::string(400, 'x');
  return Event::make(0.5 * static_cast<double>(i), static_cast<EventKind>(i % 6), text);
}

TestFrame test_frame(std::uint64_t f) {
  TestFrame fr;
  fr.time_s = static_cast<double>(f) / 30.0;
  const std::uint32_t quads = 3 + static_cast<std::uint32_t>(f % 5);
  for (std::uint32_t q = 0; q <= quads; ++q)
    for (std::uint32_t row = 0; row < 2; ++row) {
      fr.vertices_m.push_back({0.125 * q, 0.25 * row, 0.0625 * static_cast<double>(f)});
      fr.vertex_level.push_back(static_cast<std::uint8_t>((q + f) % 7));
    }
  for (std::uint32_t q = 0; q < quads; ++q) {
    const std::uint32_t a = 2 * q, b = 2 * q + 1, c = 2 * q + 2, d = 2 * q + 3;
    fr.triangles.push_back({a, c, b});
    fr.triangles.push_back({b, c, d});
  }
  for (std::size_t t = 0; t < fr.triangles.size(); ++t)
    fr.triangle_strain_energy_J_per_m3.push_back(static_cast<float>(f) * 100.0f + 0.5f * static_cast<float>(t));
  return fr;
}

bool same_row(const HapticRow& a, const HapticRow& b) {
  return a.time_s == b.time_s && a.device_position_m == b.device_position_m &&
         a.proxy_position_m == b.proxy_position_m && a.force_N == b.force_N && a.contact == b.contact &&
         a.model_version == b.model_version && a.device_fresh == b.device_fresh;
}

bool same_row(const SimRow& a, const SimRow& b) {
  return a.time_s == b.time_s && a.sim_time_s == b.sim_time_s && a.real_time_factor == b.real_time_factor &&
         a.step_ms == b.step_ms && a.nodes == b.nodes && a.tets == b.tets && a.springs == b.springs &&
         a.refines == b.refines && a.merges == b.merges && a.kinetic_J == b.kinetic_J && a.elastic_J == b.elastic_J;
}

void write_crashed_session(const std::string& path, std::uint64_t haptic_rows, std::uint64_t frames) {
  const pid_t pid = ::fork();
  ASSERT_GE(pid, 0);
  if (pid == 0) {
    try {
      SessionMetadata meta;
      meta.scene_name = "crash";
      auto w = SessionWriter::create(path, meta);
      std::vector<HapticRow> rows;
      for (std::uint64_t i = 0; i < haptic_rows; ++i) rows.push_back(haptic_row(i));
      if (!rows.empty()) w->append_haptic(rows);
      for (std::uint64_t f = 0; f < frames; ++f) w->append_mesh_frame(test_frame(f).view());
      w->flush();
      ::_exit(0);  // never closed, as after a crash
    } catch (...) {
    }
    ::_exit(1);
  }
  int status = 0;
  ASSERT_EQ(::waitpid(pid, &status, 0), pid);
  ASSERT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 0) << "the writer process failed";
}

std::string write_test_session(const std::string& path, const TestSession& c) {
  SessionMetadata m;
  m.scene_name = c.scene_name;
  m.software_version = "test";
  auto w = SessionWriter::create(path, m);
  std::vector<HapticRow> h;
  for (std::uint64_t i = 0; i < c.haptic; ++i) h.push_back(haptic_row(i));
  w->append_haptic(h);
  std::vector<SimRow> s;
  for (std::uint64_t i = 0; i < c.sim; ++i) s.push_back(sim_row(i));
  w->append_sim(s);
  for (std::uint64_t f = 0; f < c.frames; ++f) {
    TestFrame fr = test_frame(f);
    if (!c.strain) fr.triangle_strain_energy_J_per_m3.clear();
    w->append_mesh_frame(fr.view());
  }
  std::vector<Event> e;
  for (std::uint64_t i = 0; i < c.events; ++i) e.push_back(event_row(i));
  w->append_events(e);
  w->close();
  return path;
}

void write_bytes(const std::string& path, const std::string& bytes) {
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
}

std::vector<std::string> bad_session_files(const TempDir& dir) {
  std::vector<std::string> files;
  const std::string bytes = slurp(write_test_session(dir / "good.h5"));
  write_bytes(dir / "empty.h5", "");
  files.push_back(dir / "empty.h5");
  write_bytes(dir / "text.h5", "this is a scene file, not a session\nname: cantilever\n");
  files.push_back(dir / "text.h5");
  std::mt19937 rng(42);
  std::string noise(65536, '\0');
  for (char& c : noise) c = static_cast<char>(rng() & 0xff);
  write_bytes(dir / "random.h5", noise);
  files.push_back(dir / "random.h5");
  // A valid signature followed by garbage: HDF5 itself has to reject it.
  write_bytes(dir / "signature_then_noise.h5", bytes.substr(0, 8) + noise);
  files.push_back(dir / "signature_then_noise.h5");
  for (const std::size_t cut : {std::size_t{4}, std::size_t{11}, std::size_t{48}, std::size_t{500}, bytes.size() / 4,
                                bytes.size() / 2, bytes.size() - 100, bytes.size() - 1}) {
    const std::string name = dir / ("truncated_" + std::to_string(cut) + ".h5");
    write_bytes(name, bytes.substr(0, cut));
    files.push_back(name);
  }
  // A real HDF5 file that is not a session.
  const hid_t f = H5Fcreate((dir / "foreign.h5").c_str(), H5F_ACC_TRUNC, H5P_DEFAULT, H5P_DEFAULT);
  H5Fclose(f);
  files.push_back(dir / "foreign.h5");
  files.push_back(dir / "does_not_exist.h5");
  files.push_back(dir.path());  // a directory
  // Opening it blocks until a writer comes: a tool that opens before it
  // checks the file type hangs (opens_fifo_for_reading catches that).
  const std::string fifo = dir / "fifo.h5";
  if (::mkfifo(fifo.c_str(), 0600) != 0) ADD_FAILURE() << "mkfifo " << fifo << ": " << std::strerror(errno);
  files.push_back(fifo);
  return files;
}

bool opens_fifo_for_reading(const std::string& fifo, const std::function<void()>& call) {
  std::atomic<bool> done{false};
  std::exception_ptr thrown;
  std::thread caller([&] {
    try {
      call();
    } catch (...) {
      thrown = std::current_exception();
    }
    done.store(true);
  });
  bool opened = false;
  // Ends once the call does: an open for writing succeeds only while a
  // reader has the FIFO open, and it releases a reader blocked in open().
  while (!done.load()) {
    const int fd = ::open(fifo.c_str(), O_WRONLY | O_NONBLOCK | O_CLOEXEC);
    if (fd >= 0) {
      opened = true;
      ::close(fd);
    }
    std::this_thread::yield();
  }
  caller.join();
  if (thrown) std::rethrow_exception(thrown);
  return opened;
}

namespace {

template <typename T>
std::vector<T> read_all(hid_t file, const char* path, hid_t mem_type) {
  std::vector<T> out;
  const hid_t ds = H5Dopen2(file, path, H5P_DEFAULT);
  if (ds < 0) {
    ADD_FAILURE() << "cannot open " << path;
    return out;
  }
  const hid_t space = H5Dget_space(ds);
  const hssize_t n = H5Sget_simple_extent_npoints(space);
  out.resize(static_cast<std::size_t>(n));
  if (n > 0 && H5Dread(ds, mem_type, H5S_ALL, H5S_ALL, H5P_DEFAULT, out.data()) < 0)
    ADD_FAILURE() << "cannot read " << path;
  H5Sclose(space);
  H5Dclose(ds);
  return out;
}

}  // namespace

std::vector<double> read_f64(hid_t file, const char* path) { return read_all<double>(file, path, H5T_NATIVE_DOUBLE); }
std::vector<float> read_f32(hid_t file, const char* path) { return read_all<float>(file, path, H5T_NATIVE_FLOAT); }
std::vector<std::uint64_t> read_u64(hid_t file, const char* path) {
  return read_all<std::uint64_t>(file, path, H5T_NATIVE_UINT64);
}
std::vector<std::int64_t> read_i64(hid_t file, const char* path) {
  return read_all<std::int64_t>(file, path, H5T_NATIVE_INT64);
}
std::vector<std::int32_t> read_i32(hid_t file, const char* path) {
  return read_all<std::int32_t>(file, path, H5T_NATIVE_INT32);
}
std::vector<std::uint8_t> read_u8(hid_t file, const char* path) {
  return read_all<std::uint8_t>(file, path, H5T_NATIVE_UINT8);
}

std::vector<std::string> read_messages(hid_t file, const char* path) {
  const hid_t type = H5Tcopy(H5T_C_S1);
  H5Tset_size(type, kEventMessageBytes);
  H5Tset_strpad(type, H5T_STR_NULLTERM);
  H5Tset_cset(type, H5T_CSET_UTF8);  // the file says UTF-8; HDF5 converts no character sets
  std::vector<std::array<char, kEventMessageBytes>> raw =
      read_all<std::array<char, kEventMessageBytes>>(file, path, type);
  H5Tclose(type);
  std::vector<std::string> out;
  for (const auto& r : raw) out.emplace_back(r.data(), ::strnlen(r.data(), r.size()));
  return out;
}

std::vector<std::string> event_messages(const std::string& path) {
  const hid_t file = H5Fopen(path.c_str(), H5F_ACC_RDONLY, H5P_DEFAULT);
  if (file < 0) return {};
  std::vector<std::string> out = read_messages(file, "/events/message");
  H5Fclose(file);
  return out;
}

std::string root_string_attribute(const std::string& path, const char* name) {
  const hid_t file = H5Fopen(path.c_str(), H5F_ACC_RDONLY, H5P_DEFAULT);
  if (file < 0) return {};
  std::string out;
  if (!h5::read_string_attribute(file, name, &out)) out.clear();
  H5Fclose(file);
  return out;
}

int expect_session_content(hid_t file, std::uint64_t haptic, std::uint64_t sim, std::uint64_t frames,
                           std::uint64_t events) {
  int bad = 0;
  {
    const auto t = read_f64(file, "/haptic/time_s");
    const auto dev = read_f64(file, "/haptic/device_position_m");
    const auto prx = read_f64(file, "/haptic/proxy_position_m");
    const auto frc = read_f64(file, "/haptic/force_N");
    const auto con = read_u8(file, "/haptic/contact");
    const auto ver = read_u64(file, "/haptic/model_version");
    const auto fresh = read_u8(file, "/haptic/device_fresh");
    EXPECT_EQ(t.size(), haptic);
    EXPECT_EQ(dev.size(), 3 * haptic);
    EXPECT_EQ(prx.size(), 3 * haptic);
    EXPECT_EQ(frc.size(), 3 * haptic);
    EXPECT_EQ(con.size(), haptic);
    EXPECT_EQ(ver.size(), haptic);
    EXPECT_EQ(fresh.size(), haptic);
    if (t.size() != haptic || dev.size() != 3 * haptic || prx.size() != 3 * haptic || frc.size() != 3 * haptic ||
        con.size() != haptic || ver.size() != haptic || fresh.size() != haptic)
      return 1;
    for (std::uint64_t i = 0; i < haptic; ++i) {
      const HapticRow r = haptic_row(i);
      bool ok = t[i] == r.time_s && con[i] == r.contact && ver[i] == r.model_version && fresh[i] == r.device_fresh;
      for (int k = 0; k < 3; ++k)
        ok = ok && dev[3 * i + k] == r.device_position_m[k] && prx[3 * i + k] == r.proxy_position_m[k] &&
             frc[3 * i + k] == r.force_N[k];
      if (!ok && bad++ < 5) ADD_FAILURE() << "haptic row " << i << " differs";
    }
  }
  {
    const auto t = read_f64(file, "/sim/time_s");
    const auto st = read_f64(file, "/sim/sim_time_s");
    const auto rtf = read_f64(file, "/sim/real_time_factor");
    const auto ms = read_f64(file, "/sim/step_ms");
    const auto nodes = read_u64(file, "/sim/nodes");
    const auto tets = read_u64(file, "/sim/tets");
    const auto springs = read_u64(file, "/sim/springs");
    const auto refines = read_i64(file, "/sim/refines");
    const auto merges = read_i64(file, "/sim/merges");
    const auto ke = read_f64(file, "/sim/kinetic_J");
    const auto ee = read_f64(file, "/sim/elastic_J");
    EXPECT_EQ(t.size(), sim);
    for (const std::size_t n : {st.size(), rtf.size(), ms.size(), nodes.size(), tets.size(), springs.size(),
                                refines.size(), merges.size(), ke.size(), ee.size()})
      if (n != sim) {
        ADD_FAILURE() << "a /sim column has " << n << " rows, expected " << sim;
        return bad + 1;
      }
    if (t.size() != sim) return bad + 1;
    for (std::uint64_t i = 0; i < sim; ++i) {
      const SimRow r = sim_row(i);
      const bool ok = t[i] == r.time_s && st[i] == r.sim_time_s && rtf[i] == r.real_time_factor && ms[i] == r.step_ms &&
                      nodes[i] == r.nodes && tets[i] == r.tets && springs[i] == r.springs && refines[i] == r.refines &&
                      merges[i] == r.merges && ke[i] == r.kinetic_J && ee[i] == r.elastic_J;
      if (!ok && bad++ < 5) ADD_FAILURE() << "sim row " << i << " differs";
    }
  }
  {
    const auto ft = read_f64(file, "/mesh/frame_time_s");
    const auto voff = read_u64(file, "/mesh/vertex_offset");
    const auto vcnt = read_u64(file, "/mesh/vertex_count");
    const auto toff = read_u64(file, "/mesh/triangle_offset");
    const auto tcnt = read_u64(file, "/mesh/triangle_count");
    const auto verts = read_f32(file, "/mesh/vertices_m");
    const auto tris = read_i32(file, "/mesh/triangles");
    const auto lev = read_u8(file, "/mesh/vertex_level");
    const auto strain = read_f32(file, "/mesh/triangle_strain_energy_J_per_m3");
    EXPECT_EQ(ft.size(), frames);
    if (ft.size() != frames || voff.size() != frames || vcnt.size() != frames || toff.size() != frames ||
        tcnt.size() != frames)
      return bad + 1;
    std::uint64_t v_end = 0, t_end = 0;
    for (std::uint64_t f = 0; f < frames; ++f) {
      const TestFrame fr = test_frame(f);
      bool ok = ft[f] == fr.time_s && voff[f] == v_end && toff[f] == t_end && vcnt[f] == fr.vertices_m.size() &&
                tcnt[f] == fr.triangles.size() && 3 * (v_end + vcnt[f]) <= verts.size() &&
                v_end + vcnt[f] <= lev.size() && 3 * (t_end + tcnt[f]) <= tris.size() &&
                t_end + tcnt[f] <= strain.size();
      if (ok) {
        for (std::size_t v = 0; v < fr.vertices_m.size(); ++v) {
          for (int k = 0; k < 3; ++k) ok = ok && verts[3 * (v_end + v) + k] == static_cast<float>(fr.vertices_m[v][k]);
          ok = ok && lev[v_end + v] == fr.vertex_level[v];
        }
        for (std::size_t t = 0; t < fr.triangles.size(); ++t)
          for (int k = 0; k < 3; ++k)
            ok = ok && tris[3 * (t_end + t) + k] == static_cast<std::int32_t>(fr.triangles[t][k]);
        for (std::size_t t = 0; t < fr.triangles.size(); ++t)
          ok = ok && strain[t_end + t] == fr.triangle_strain_energy_J_per_m3[t];
      }
      if (!ok && bad++ < 5) ADD_FAILURE() << "mesh frame " << f << " differs";
      v_end += fr.vertices_m.size();
      t_end += fr.triangles.size();
    }
  }
  {
    const auto t = read_f64(file, "/events/time_s");
    const auto kind = read_i32(file, "/events/kind");
    const auto msg = read_messages(file, "/events/message");
    EXPECT_EQ(t.size(), events);
    if (t.size() != events || kind.size() != events || msg.size() != events) return bad + 1;
    for (std::uint64_t i = 0; i < events; ++i) {
      const Event e = event_row(i);
      const bool ok =
          t[i] == e.time_s && kind[i] == static_cast<std::int32_t>(e.kind) && msg[i] == std::string(e.message);
      if (!ok && bad++ < 5) ADD_FAILURE() << "event " << i << " differs: '" << msg[i] << "'";
    }
  }
  return bad;
}

hid_t open_for_edit(const std::string& path) {
  const hid_t fapl = H5Pcreate(H5P_FILE_ACCESS);
  H5Pset_libver_bounds(fapl, H5F_LIBVER_LATEST, H5F_LIBVER_LATEST);
  const hid_t file = H5Fopen(path.c_str(), H5F_ACC_RDWR, fapl);
  H5Pclose(fapl);
  return file;
}

void make_version_1(const std::string& path) {
  const hid_t file = open_for_edit(path);
  ASSERT_GE(file, 0) << path;
  EXPECT_GE(H5Ldelete(file, kDatasets[kMeshTriangleStrain].path, H5P_DEFAULT), 0);
  EXPECT_GE(H5Ldelete(file, kDatasets[kHapticDeviceFresh].path, H5P_DEFAULT), 0);
  EXPECT_GE(H5Adelete(file, kAttrFormatVersion), 0);
  h5::write_i64_attribute(file, kAttrFormatVersion, 1);
  H5Fclose(file);
}

void make_version_2(const std::string& path) {
  const hid_t file = open_for_edit(path);
  ASSERT_GE(file, 0) << path;
  EXPECT_GE(H5Ldelete(file, kDatasets[kHapticDeviceFresh].path, H5P_DEFAULT), 0);
  EXPECT_GE(H5Adelete(file, kAttrFormatVersion), 0);
  h5::write_i64_attribute(file, kAttrFormatVersion, 2);
  H5Fclose(file);
}

void overwrite_element(const std::string& path, const char* dataset, std::uint64_t row, std::uint64_t column,
                       hid_t mem_type, const void* value) {
  const hid_t file = open_for_edit(path);
  ASSERT_GE(file, 0) << path;
  const hid_t ds = H5Dopen2(file, dataset, H5P_DEFAULT);
  ASSERT_GE(ds, 0) << dataset;
  const hid_t space = H5Dget_space(ds);
  const int rank = H5Sget_simple_extent_ndims(space);
  ASSERT_TRUE(rank == 1 || rank == 2) << dataset;
  const hsize_t start[2] = {row, column}, count[2] = {1, 1};
  const hid_t mem = H5Screate_simple(1, count, nullptr);
  EXPECT_GE(H5Sselect_hyperslab(space, H5S_SELECT_SET, start, nullptr, count, nullptr), 0);
  EXPECT_GE(H5Dwrite(ds, mem_type, mem, space, H5P_DEFAULT, value), 0) << dataset;
  H5Sclose(mem);
  H5Sclose(space);
  H5Dclose(ds);
  H5Fclose(file);
}

namespace {

template <typename T>
void overwrite(const std::string& path, const char* dataset, std::uint64_t row, hid_t mem_type, T value,
               std::uint64_t column = 0) {
  overwrite_element(path, dataset, row, column, mem_type, &value);
}

}  // namespace

void overwrite_f32(const std::string& path, const char* dataset, std::uint64_t row, float value) {
  overwrite(path, dataset, row, H5T_NATIVE_FLOAT, value);
}

void overwrite_f64(const std::string& path, const char* dataset, std::uint64_t row, double value) {
  overwrite(path, dataset, row, H5T_NATIVE_DOUBLE, value);
}

void overwrite_f64_at(const std::string& path, const char* dataset, std::uint64_t row, std::uint64_t column,
                      double value) {
  overwrite(path, dataset, row, H5T_NATIVE_DOUBLE, value, column);
}

bool have_system_h5py() { return std::system("/usr/bin/python3 -c 'import h5py' >/dev/null 2>&1") == 0; }

}  // namespace tissue::record::testing
