// The HDF5 helpers of daemon/record/h5_util: id ownership, HDF5's error
// printing kept off stderr, error messages that carry HDF5's (or the OS's)
// reason, and attribute / extent readers that answer "no" instead of reading
// garbage when an attribute is missing or of another type or shape.
#include "record/h5_util.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <limits>
#include <string>
#include <vector>

#include "record/record_types.hpp"
#include "record_test_support.hpp"

namespace tissue::record::h5 {
namespace {

using testing::TempDir;

// A fresh file with the latest format (what the session writer uses, and
// what SWMR needs). Fails the test when it cannot be made.
Handle create_file(const std::string& path) {
  Handle fapl(H5Pcreate(H5P_FILE_ACCESS));
  H5Pset_libver_bounds(fapl.get(), H5F_LIBVER_LATEST, H5F_LIBVER_LATEST);
  Handle file(H5Fcreate(path.c_str(), H5F_ACC_TRUNC, H5P_DEFAULT, fapl.get()));
  EXPECT_TRUE(file.valid()) << path;
  return file;
}

bool id_is_open(hid_t id) { return H5Iis_valid(id) > 0; }

// An attribute of any stored type (scalar unless `space_id` is given), for
// the readers to refuse or convert. Takes `space_id`.
void create_attribute(hid_t object, const char* name, hid_t file_type, hid_t mem_type, const void* value,
                      hid_t space_id = H5I_INVALID_HID) {
  Handle space(space_id >= 0 ? space_id : H5Screate(H5S_SCALAR));
  Handle attr(H5Acreate2(object, name, file_type, space.get(), H5P_DEFAULT, H5P_DEFAULT));
  ASSERT_TRUE(attr.valid()) << name;
  ASSERT_GE(H5Awrite(attr.get(), mem_type, value), 0) << name;
}

// The stored (file) type of an attribute.
Handle attribute_type(hid_t object, const char* name) {
  Handle attr(H5Aopen(object, name, H5P_DEFAULT));
  EXPECT_TRUE(attr.valid()) << name;
  return Handle(attr ? H5Aget_type(attr.get()) : H5I_INVALID_HID);
}

// ---------------------------------------------------------------- Handle

TEST(H5Util, HandleClosesEveryKindOfIdItOwns) {
  TempDir dir;
  QuietErrors quiet;
  const hid_t file = H5Fcreate((dir / "h.h5").c_str(), H5F_ACC_TRUNC, H5P_DEFAULT, H5P_DEFAULT);
  ASSERT_GE(file, 0);
  const hsize_t dims[1] = {4};
  const hid_t space = H5Screate_simple(1, dims, nullptr);
  const hid_t group = H5Gcreate2(file, "/g", H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT);
  const hid_t dataset = H5Dcreate2(file, "/d", H5T_STD_I32LE, space, H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT);
  const hid_t type = H5Tcopy(H5T_NATIVE_DOUBLE);
  const hid_t scalar = H5Screate(H5S_SCALAR);
  const hid_t attr = H5Acreate2(group, "a", H5T_STD_I64LE, scalar, H5P_DEFAULT, H5P_DEFAULT);
  const hid_t plist = H5Pcreate(H5P_DATASET_XFER);
  const hid_t error_class = H5Eregister_class("tissue test", "tissue", "0");  // the fallback: H5Idec_ref
  for (const hid_t id : {space, group, dataset, type, scalar, attr, plist, error_class}) ASSERT_GE(id, 0);

  {
    // Closed by reset(), which reports success...
    Handle h(attr);
    EXPECT_TRUE(h.reset());
    EXPECT_FALSE(h.valid());
    EXPECT_FALSE(id_is_open(attr));
    EXPECT_TRUE(h.reset()) << "resetting an empty handle is a no-op";
  }
  for (const hid_t id : {dataset, group, type, scalar, space, plist, error_class}) {
    SCOPED_TRACE(H5Iget_type(id));
    {
      Handle h(id);  // ...and by the destructor.
      EXPECT_TRUE(h.valid());
      EXPECT_EQ(h.get(), id);
    }
    EXPECT_FALSE(id_is_open(id));
  }
  // The file last, once nothing in it is open.
  {
    Handle h(file);
    EXPECT_TRUE(h.reset());
  }
  EXPECT_FALSE(id_is_open(file));
}

TEST(H5Util, HandleMovesOwnershipAndReleaseGivesItUp) {
  Handle empty;
  EXPECT_FALSE(empty.valid());
  EXPECT_FALSE(static_cast<bool>(empty));
  EXPECT_EQ(empty.get(), H5I_INVALID_HID);

  Handle a(H5Screate(H5S_SCALAR));
  const hid_t id = a.get();
  ASSERT_TRUE(a.valid());
  Handle b(std::move(a));
  EXPECT_FALSE(a.valid());  // NOLINT(bugprone-use-after-move): the moved-from state is the contract
  EXPECT_EQ(b.get(), id);
  EXPECT_TRUE(id_is_open(id));

  Handle c(H5Screate(H5S_SCALAR));
  const hid_t replaced = c.get();
  c = std::move(b);  // the id c held is closed, b's moves over
  EXPECT_FALSE(id_is_open(replaced));
  EXPECT_FALSE(b.valid());  // NOLINT(bugprone-use-after-move)
  EXPECT_EQ(c.get(), id);
  Handle& alias = c;
  c = std::move(alias);  // self-assignment keeps the id open
  EXPECT_EQ(c.get(), id);
  EXPECT_TRUE(id_is_open(id));

  const hid_t released = c.release();
  EXPECT_EQ(released, id);
  EXPECT_FALSE(c.valid());
  EXPECT_TRUE(id_is_open(id)) << "release() must not close";
  EXPECT_GE(H5Sclose(released), 0);
}

TEST(H5Util, ResetReportsAFailedClose) {
  QuietErrors quiet;
  Handle h(H5Screate(H5S_SCALAR));
  ASSERT_TRUE(h.valid());
  ASSERT_GE(H5Sclose(h.get()), 0);  // closed behind the handle's back: its close must fail
  EXPECT_FALSE(h.reset());
  EXPECT_FALSE(h.valid()) << "a failed close still gives the id up";
  EXPECT_TRUE(h.reset());
}

// ---------------------------------------------------------------- errors

herr_t count_reports(hid_t /*stack*/, void* client_data) {
  ++*static_cast<int*>(client_data);
  return 0;
}

// A call that fails inside the HDF5 API (and so reaches the automatic printer).
void fail_an_hdf5_call() { EXPECT_LT(H5Dopen2(H5I_INVALID_HID, "/nothing", H5P_DEFAULT), 0); }

TEST(H5Util, QuietErrorsSilencesTheAutomaticPrinterAndRestoresTheCallers) {
  H5E_auto2_t saved_func = nullptr;
  void* saved_data = nullptr;
  ASSERT_GE(H5Eget_auto2(H5E_DEFAULT, &saved_func, &saved_data), 0);
  int reports = 0;
  ASSERT_GE(H5Eset_auto2(H5E_DEFAULT, count_reports, &reports), 0);
  fail_an_hdf5_call();
  ASSERT_EQ(reports, 1) << "the counting printer is not called: the test cannot see anything";
  {
    QuietErrors outer;
    fail_an_hdf5_call();
    {
      QuietErrors inner;
      fail_an_hdf5_call();
    }
    fail_an_hdf5_call();  // the inner one restored the outer's silence
    EXPECT_EQ(reports, 1) << "HDF5 printed its error stack inside QuietErrors";
  }
  H5E_auto2_t func = nullptr;
  void* data = nullptr;
  ASSERT_GE(H5Eget_auto2(H5E_DEFAULT, &func, &data), 0);
  EXPECT_EQ(func, &count_reports);
  EXPECT_EQ(data, &reports);
  fail_an_hdf5_call();
  EXPECT_EQ(reports, 2) << "the caller's printer was not restored";
  H5Eset_auto2(H5E_DEFAULT, saved_func, saved_data);
}

TEST(H5Util, LastErrorIsEmptyWithoutAnErrorAndDescribeThenAddsNothing) {
  H5Eclear2(H5E_DEFAULT);
  EXPECT_EQ(last_error(), "");
  EXPECT_EQ(describe("cannot flush /haptic/time_s"), "cannot flush /haptic/time_s");
}

TEST(H5Util, LastErrorIsTheOperatingSystemsReasonWhenHdf5CarriesOne) {
  TempDir dir;
  QuietErrors quiet;
  const std::string missing = dir / "missing.h5";
  EXPECT_LT(H5Fopen(missing.c_str(), H5F_ACC_RDONLY, H5P_DEFAULT), 0);
  // HDF5's own stack says "unable to open file: name = '...', tent_flags =
  // 0" around "... errno = 2, error message = 'No such file or directory'":
  // only the OS part is for the user.
  EXPECT_EQ(last_error(), "No such file or directory");
  EXPECT_EQ(describe("'" + missing + "': cannot be opened"),
            "'" + missing + "': cannot be opened: No such file or directory");
}

TEST(H5Util, LastErrorWithoutAnOsReasonIsTheInnermostMessageWithOneLevelOfContext) {
  TempDir dir;
  QuietErrors quiet;
  Handle file = create_file(dir / "f.h5");
  ASSERT_TRUE(file.valid());
  EXPECT_LT(H5Dopen2(file.get(), "/no_such_dataset", H5P_DEFAULT), 0);
  // Every description on the stack, innermost first.
  std::vector<std::string> stack;
  H5Ewalk2(
      H5E_DEFAULT, H5E_WALK_UPWARD,
      [](unsigned, const H5E_error2_t* e, void* out) -> herr_t {
        static_cast<std::vector<std::string>*>(out)->emplace_back(e->desc ? e->desc : "");
        return 0;
      },
      &stack);
  ASSERT_GE(stack.size(), 2u) << "HDF5 reported a one-level stack; the case below needs two";
  ASSERT_NE(stack[0], stack[1]);
  const std::string reason = last_error();
  // "<the level above> (<the innermost>)": the innermost message alone is
  // often cryptic, the outermost alone too vague.
  EXPECT_EQ(reason, stack[1] + " (" + stack[0] + ")");
  EXPECT_NE(reason.find("'no_such_dataset' doesn't exist"), std::string::npos) << reason;
  EXPECT_EQ(describe("cannot open dataset /no_such_dataset"), "cannot open dataset /no_such_dataset: " + reason);
}

// ---------------------------------------------------------------- attributes

TEST(H5Util, AttributesRoundTripWithTheDocumentedFileTypes) {
  TempDir dir;
  QuietErrors quiet;
  Handle file = create_file(dir / "a.h5");
  ASSERT_TRUE(file.valid());
  const hid_t f = file.get();
  const std::string utf8 = "cantilever \xc3\xa9\xe2\x82\xac";  // é€
  write_string_attribute(f, "s", utf8);
  write_string_attribute(f, "empty", "");
  write_u8_attribute(f, "u8", 255);
  write_i64_attribute(f, "min", std::numeric_limits<std::int64_t>::min());
  write_i64_attribute(f, "max", std::numeric_limits<std::int64_t>::max());
  write_f64_attribute(f, "x", -1.25e-300);
  write_f64_attribute(f, "nan", std::numeric_limits<double>::quiet_NaN());

  std::string s;
  ASSERT_TRUE(read_string_attribute(f, "s", &s));
  EXPECT_EQ(s, utf8);
  ASSERT_TRUE(read_string_attribute(f, "empty", &s));
  EXPECT_EQ(s, "");
  std::int64_t i = 0;
  ASSERT_TRUE(read_i64_attribute(f, "u8", &i));  // closed_cleanly is a u8 read this way
  EXPECT_EQ(i, 255);
  ASSERT_TRUE(read_i64_attribute(f, "min", &i));
  EXPECT_EQ(i, std::numeric_limits<std::int64_t>::min());
  ASSERT_TRUE(read_i64_attribute(f, "max", &i));
  EXPECT_EQ(i, std::numeric_limits<std::int64_t>::max());
  double x = 0.0;
  ASSERT_TRUE(read_f64_attribute(f, "x", &x));
  EXPECT_EQ(x, -1.25e-300);
  ASSERT_TRUE(read_f64_attribute(f, "nan", &x));  // duration_s is NaN until the clean close
  EXPECT_TRUE(std::isnan(x));

  // docs/session-format.md: little-endian standard types, fixed-length
  // NUL-terminated UTF-8 strings of the value's size.
  EXPECT_GT(H5Tequal(attribute_type(f, "u8").get(), H5T_STD_U8LE), 0);
  EXPECT_GT(H5Tequal(attribute_type(f, "max").get(), H5T_STD_I64LE), 0);
  EXPECT_GT(H5Tequal(attribute_type(f, "x").get(), H5T_IEEE_F64LE), 0);
  const Handle st = attribute_type(f, "s");
  EXPECT_EQ(H5Tget_class(st.get()), H5T_STRING);
  EXPECT_EQ(H5Tis_variable_str(st.get()), 0);
  EXPECT_EQ(H5Tget_size(st.get()), utf8.size() + 1);
  EXPECT_EQ(H5Tget_strpad(st.get()), H5T_STR_NULLTERM);
  EXPECT_EQ(H5Tget_cset(st.get()), H5T_CSET_UTF8);

  // Existing attributes are rewritten, not duplicated.
  write_i64_attribute(f, "max", 7);
  ASSERT_TRUE(read_i64_attribute(f, "max", &i));
  EXPECT_EQ(i, 7);
}

TEST(H5Util, StringAttributesKeepTheirReservedRoomAndAreRewrittenInPlaceUnderSwmr) {
  TempDir dir;
  QuietErrors quiet;
  Handle file = create_file(dir / "swmr.h5");
  ASSERT_TRUE(file.valid());
  const hid_t f = file.get();
  write_string_attribute(f, "end_time_utc", "", 32);  // what the writer does for kAttrEndTime
  EXPECT_EQ(H5Tget_size(attribute_type(f, "end_time_utc").get()), 32u);
  write_string_attribute(f, "short", "a longer value than stored_bytes", 4);  // the value wins
  EXPECT_EQ(H5Tget_size(attribute_type(f, "short").get()), 33u);
  write_i64_attribute(f, "closed_cleanly", 0);
  ASSERT_GE(H5Fstart_swmr_write(f), 0);

  // In SWMR mode: existing attributes are rewritten in place, a string up to
  // its reserved room.
  const std::string end = "2024-05-01T12:00:00.123Z";
  write_string_attribute(f, "end_time_utc", end);
  write_i64_attribute(f, "closed_cleanly", 1);
  std::string s;
  ASSERT_TRUE(read_string_attribute(f, "end_time_utc", &s));
  EXPECT_EQ(s, end);
  EXPECT_EQ(H5Tget_size(attribute_type(f, "end_time_utc").get()), 32u) << "the stored size must not change";
  // Longer than the room: cut to it (31 bytes and the NUL), never past it.
  write_string_attribute(f, "end_time_utc", std::string(40, 'x'));
  ASSERT_TRUE(read_string_attribute(f, "end_time_utc", &s));
  EXPECT_EQ(s, std::string(31, 'x'));
  std::int64_t clean = 0;
  ASSERT_TRUE(read_i64_attribute(f, "closed_cleanly", &clean));
  EXPECT_EQ(clean, 1);
}

TEST(H5Util, WritingAnAttributeThatCannotTakeTheValueIsAnErrorNamingIt) {
  TempDir dir;
  QuietErrors quiet;
  Handle file = create_file(dir / "w.h5");
  ASSERT_TRUE(file.valid());
  write_string_attribute(file.get(), "format_version", "two");
  try {
    write_i64_attribute(file.get(), "format_version", 2);  // an integer into a string attribute
    FAIL() << "wrote an integer into a string attribute";
  } catch (const RecordError& e) {
    const std::string what = e.what();
    EXPECT_EQ(what.rfind("cannot write attribute format_version: ", 0), 0u) << what;
    EXPECT_GT(what.size(), std::string("cannot write attribute format_version: ").size()) << "no reason given";
  }
  std::string s;
  ASSERT_TRUE(read_string_attribute(file.get(), "format_version", &s));
  EXPECT_EQ(s, "two");
  try {
    write_u8_attribute(H5I_INVALID_HID, "closed_cleanly", 1);
    FAIL() << "wrote an attribute on no object";
  } catch (const RecordError& e) {
    EXPECT_EQ(std::string(e.what()).rfind("cannot create attribute closed_cleanly", 0), 0u) << e.what();
  }
}

TEST(H5Util, ReadersRefuseMissingWrongTypeAndWrongShapeAttributesLeavingTheOutputAlone) {
  TempDir dir;
  QuietErrors quiet;
  Handle file = create_file(dir / "r.h5");
  ASSERT_TRUE(file.valid());
  const hid_t f = file.get();
  write_i64_attribute(f, "an_int", 5);
  write_f64_attribute(f, "a_double", 0.5);
  write_string_attribute(f, "a_string", "text");
  {  // two integers, two doubles
    const hsize_t two[1] = {2};
    const std::int64_t ints[2] = {1, 2};
    create_attribute(f, "int_pair", H5T_STD_I64LE, H5T_NATIVE_INT64, ints, H5Screate_simple(1, two, nullptr));
    const double doubles[2] = {1.0, 2.0};
    create_attribute(f, "double_pair", H5T_IEEE_F64LE, H5T_NATIVE_DOUBLE, doubles, H5Screate_simple(1, two, nullptr));
  }
  {  // a variable-length string (h5py's default for str attributes)
    Handle vl(H5Tcopy(H5T_C_S1));
    H5Tset_size(vl.get(), H5T_VARIABLE);
    const char* text = "variable";
    create_attribute(f, "vl_string", vl.get(), vl.get(), &text);
  }
  {  // two fixed-length strings
    Handle t(H5Tcopy(H5T_C_S1));
    H5Tset_size(t.get(), 4);
    const hsize_t two[1] = {2};
    create_attribute(f, "string_pair", t.get(), t.get(), "abcdefgh", H5Screate_simple(1, two, nullptr));
  }
  constexpr std::int64_t kUntouchedI = -77;
  constexpr double kUntouchedF = -77.5;
  const std::string kUntouchedS = "untouched";
  std::int64_t i = kUntouchedI;
  double x = kUntouchedF;
  std::string s = kUntouchedS;
  // A floating-point value is not read as an integer (0.5 converted to 0).
  for (const char* name : {"missing", "a_double", "a_string", "int_pair", "vl_string", "string_pair"}) {
    SCOPED_TRACE(name);
    EXPECT_FALSE(read_i64_attribute(f, name, &i));
    EXPECT_EQ(i, kUntouchedI);
  }
  for (const char* name : {"missing", "a_string", "double_pair", "vl_string"}) {
    SCOPED_TRACE(name);
    EXPECT_FALSE(read_f64_attribute(f, name, &x));
    EXPECT_EQ(x, kUntouchedF);
  }
  for (const char* name : {"missing", "an_int", "a_double", "vl_string", "string_pair"}) {
    SCOPED_TRACE(name);
    EXPECT_FALSE(read_string_attribute(f, name, &s));
    EXPECT_EQ(s, kUntouchedS);
  }
  // No object at all.
  EXPECT_FALSE(read_i64_attribute(H5I_INVALID_HID, "an_int", &i));
  EXPECT_FALSE(read_f64_attribute(H5I_INVALID_HID, "a_double", &x));
  EXPECT_FALSE(read_string_attribute(H5I_INVALID_HID, "a_string", &s));
  EXPECT_EQ(i, kUntouchedI);
  EXPECT_EQ(x, kUntouchedF);
  EXPECT_EQ(s, kUntouchedS);
  // Integers read as doubles (exactly, below 2^53).
  ASSERT_TRUE(read_f64_attribute(f, "an_int", &x));
  EXPECT_EQ(x, 5.0);
  // What each holds, for the errors of the readers that refuse it.
  EXPECT_EQ(describe_attribute(f, "missing"), "missing");
  EXPECT_EQ(describe_attribute(f, "an_int"), "an integer");
  EXPECT_EQ(describe_attribute(f, "a_double"), "a floating-point value (0.5)");
  EXPECT_EQ(describe_attribute(f, "a_string"), "a string");
  EXPECT_EQ(describe_attribute(f, "vl_string"), "a string");
  EXPECT_EQ(describe_attribute(f, "int_pair"), "2 values, not one");
}

TEST(H5Util, StringsOfOtherWritersReadWithoutTheirPadding) {
  TempDir dir;
  QuietErrors quiet;
  Handle file = create_file(dir / "p.h5");
  ASSERT_TRUE(file.valid());
  const auto make = [&](const char* name, std::size_t size, H5T_str_t pad, H5T_cset_t cset, const char* bytes) {
    Handle t(H5Tcopy(H5T_C_S1));
    H5Tset_size(t.get(), size);
    H5Tset_strpad(t.get(), pad);
    H5Tset_cset(t.get(), cset);
    create_attribute(file.get(), name, t.get(), t.get(), bytes);
  };
  make("nullpad", 8, H5T_STR_NULLPAD, H5T_CSET_ASCII, "abc\0\0\0\0\0");
  make("full", 5, H5T_STR_NULLPAD, H5T_CSET_UTF8, "abcde");  // no NUL at all: all 5 bytes are text
  std::string s;
  ASSERT_TRUE(read_string_attribute(file.get(), "nullpad", &s));
  EXPECT_EQ(s, "abc");
  ASSERT_TRUE(read_string_attribute(file.get(), "full", &s));
  EXPECT_EQ(s, "abcde");
}

// ---------------------------------------------------------------- rows

TEST(H5Util, RowsIsTheFirstExtentOfAColumnOrTableAndMinusOneOtherwise) {
  TempDir dir;
  QuietErrors quiet;
  Handle file = create_file(dir / "rows.h5");
  ASSERT_TRUE(file.valid());
  const auto dataset = [&](const char* name, int rank, const hsize_t* dims, const hsize_t* max = nullptr,
                           hid_t dcpl = H5P_DEFAULT) {
    Handle space(rank == 0 ? H5Screate(H5S_SCALAR) : H5Screate_simple(rank, dims, max));
    return Handle(H5Dcreate2(file.get(), name, H5T_NATIVE_DOUBLE, space.get(), H5P_DEFAULT, dcpl, H5P_DEFAULT));
  };
  const hsize_t five[1] = {5}, seven_by_three[2] = {7, 3}, cube[3] = {2, 2, 2}, none[1] = {0};
  const hsize_t unlimited[2] = {H5S_UNLIMITED, 3}, chunk[2] = {16, 3};
  Handle dcpl(H5Pcreate(H5P_DATASET_CREATE));
  H5Pset_chunk(dcpl.get(), 2, chunk);
  const hsize_t start_rows[2] = {0, 3};
  Handle column = dataset("/column", 1, five);
  Handle table = dataset("/table", 2, seven_by_three);
  Handle empty = dataset("/empty", 1, none);
  Handle growing = dataset("/growing", 2, start_rows, unlimited, dcpl.get());
  Handle scalar = dataset("/scalar", 0, nullptr);
  Handle rank3 = dataset("/rank3", 3, cube);
  for (const Handle* h : {&column, &table, &empty, &growing, &scalar, &rank3}) ASSERT_TRUE(h->valid());

  EXPECT_EQ(rows(column.get()), 5);
  EXPECT_EQ(rows(table.get()), 7);
  EXPECT_EQ(rows(empty.get()), 0);
  EXPECT_EQ(rows(growing.get()), 0);
  const hsize_t grown[2] = {40, 3};
  ASSERT_GE(H5Dset_extent(growing.get(), grown), 0);
  EXPECT_EQ(rows(growing.get()), 40) << "the current extent, not the one at creation";
  EXPECT_EQ(rows(scalar.get()), -1);
  EXPECT_EQ(rows(rank3.get()), -1);
  EXPECT_EQ(rows(H5I_INVALID_HID), -1);
  EXPECT_EQ(rows(file.get()), -1);  // not a dataset
}

}  // namespace
}  // namespace tissue::record::h5
