#include "record/h5_util.hpp"

#include <algorithm>
#include <cstdio>
#include <cstring>
#include <vector>

#include "record/record_types.hpp"

namespace tissue::record::h5 {

bool Handle::reset() {
  if (id_ < 0) return true;
  herr_t status = 0;
  switch (H5Iget_type(id_)) {
    case H5I_FILE:
      status = H5Fclose(id_);
      break;
    case H5I_GROUP:
      status = H5Gclose(id_);
      break;
    case H5I_DATASET:
      status = H5Dclose(id_);
      break;
    case H5I_DATASPACE:
      status = H5Sclose(id_);
      break;
    case H5I_DATATYPE:
      status = H5Tclose(id_);
      break;
    case H5I_ATTR:
      status = H5Aclose(id_);
      break;
    case H5I_GENPROP_LST:
      status = H5Pclose(id_);
      break;
    default:
      status = H5Idec_ref(id_);
      break;
  }
  id_ = H5I_INVALID_HID;
  return status >= 0;
}

QuietErrors::QuietErrors() {
  H5Eget_auto2(H5E_DEFAULT, &old_func_, &old_data_);
  H5Eset_auto2(H5E_DEFAULT, nullptr, nullptr);
}

QuietErrors::~QuietErrors() { H5Eset_auto2(H5E_DEFAULT, old_func_, old_data_); }

namespace {

struct WalkState {
  std::vector<std::string> descriptions;  // innermost first
};

herr_t collect(unsigned /*n*/, const H5E_error2_t* err, void* client_data) {
  auto* state = static_cast<WalkState*>(client_data);
  if (err->desc != nullptr && err->desc[0] != '\0') state->descriptions.emplace_back(err->desc);
  return 0;
}

// HDF5's low-level I/O messages carry the OS reason as
// "errno = 28, error message = 'No space left on device'": that is the part
// a user needs, the rest (buffers, offsets) is noise.
std::string os_reason(const std::string& desc) {
  const std::string key = "error message = '";
  const auto at = desc.find(key);
  if (at == std::string::npos) return {};
  const auto end = desc.find('\'', at + key.size());
  if (end == std::string::npos) return {};
  return desc.substr(at + key.size(), end - at - key.size());
}

}  // namespace

std::string last_error() {
  WalkState state;
  H5Ewalk2(H5E_DEFAULT, H5E_WALK_UPWARD, collect, &state);
  if (state.descriptions.empty()) return {};
  for (const std::string& d : state.descriptions) {
    const std::string os = os_reason(d);
    if (!os.empty()) return os;
  }
  std::string reason = state.descriptions.front();
  // The innermost message alone can be cryptic ("bad object header
  // version number"); one level of context above it helps.
  if (state.descriptions.size() >= 2 && state.descriptions[1] != reason)
    reason = state.descriptions[1] + " (" + reason + ")";
  return reason;
}

std::string describe(const std::string& what) {
  const std::string reason = last_error();
  return reason.empty() ? what : what + ": " + reason;
}

namespace {

void write_attribute(hid_t object, const char* name, hid_t file_type, hid_t mem_type, const void* value) {
  Handle space(H5Screate(H5S_SCALAR));
  if (!space) throw RecordError(describe(std::string("cannot create dataspace for attribute ") + name));
  Handle attr;
  if (H5Aexists(object, name) > 0)
    attr = Handle(H5Aopen(object, name, H5P_DEFAULT));
  else
    attr = Handle(H5Acreate2(object, name, file_type, space.get(), H5P_DEFAULT, H5P_DEFAULT));
  if (!attr) throw RecordError(describe(std::string("cannot create attribute ") + name));
  if (H5Awrite(attr.get(), mem_type, value) < 0)
    throw RecordError(describe(std::string("cannot write attribute ") + name));
}

Handle string_type(std::size_t bytes) {
  Handle t(H5Tcopy(H5T_C_S1));
  H5Tset_size(t.get(), bytes);
  H5Tset_strpad(t.get(), H5T_STR_NULLTERM);
  H5Tset_cset(t.get(), H5T_CSET_UTF8);
  return t;
}

}  // namespace

void write_string_attribute(hid_t object, const char* name, const std::string& value, std::size_t stored_bytes) {
  // Fixed-length, NUL-terminated: every reader (C, h5py, h5dump) handles it
  // without variable-length memory to reclaim. An existing attribute keeps
  // its stored size (HDF5 converts between string sizes on write).
  Handle file_type = string_type(std::max(value.size() + 1, stored_bytes));
  Handle mem_type = string_type(value.size() + 1);
  write_attribute(object, name, file_type.get(), mem_type.get(), value.c_str());
}

void write_u8_attribute(hid_t object, const char* name, std::uint8_t value) {
  write_attribute(object, name, H5T_STD_U8LE, H5T_NATIVE_UINT8, &value);
}

void write_i64_attribute(hid_t object, const char* name, std::int64_t value) {
  write_attribute(object, name, H5T_STD_I64LE, H5T_NATIVE_INT64, &value);
}

void write_f64_attribute(hid_t object, const char* name, double value) {
  write_attribute(object, name, H5T_IEEE_F64LE, H5T_NATIVE_DOUBLE, &value);
}

bool read_string_attribute(hid_t object, const char* name, std::string* out) {
  if (H5Aexists(object, name) <= 0) return false;
  Handle attr(H5Aopen(object, name, H5P_DEFAULT));
  if (!attr) return false;
  Handle type(H5Aget_type(attr.get()));
  if (!type || H5Tget_class(type.get()) != H5T_STRING || H5Tis_variable_str(type.get()) != 0) return false;
  Handle space(H5Aget_space(attr.get()));
  if (!space || H5Sget_simple_extent_npoints(space.get()) != 1) return false;
  const std::size_t bytes = H5Tget_size(type.get());
  if (bytes == 0 || bytes > (std::size_t{1} << 30)) return false;
  std::vector<char> buf(bytes + 1, '\0');
  // Same size and character set as stored (HDF5 converts no character
  // sets); NUL padding reads NULLTERM and NULLPAD strings alike.
  Handle mem(H5Tcopy(type.get()));
  H5Tset_strpad(mem.get(), H5T_STR_NULLPAD);
  if (H5Aread(attr.get(), mem.get(), buf.data()) < 0) return false;
  *out = std::string(buf.data(), ::strnlen(buf.data(), bytes));
  return true;
}

bool read_i64_attribute(hid_t object, const char* name, std::int64_t* out) {
  if (H5Aexists(object, name) <= 0) return false;
  Handle attr(H5Aopen(object, name, H5P_DEFAULT));
  Handle space(attr ? H5Aget_space(attr.get()) : H5I_INVALID_HID);
  if (!space || H5Sget_simple_extent_npoints(space.get()) != 1) return false;
  // Integers only: HDF5 converts a floating-point attribute on read,
  // truncating (format_version 2.5 read as 2).
  Handle type(H5Aget_type(attr.get()));
  if (!type || H5Tget_class(type.get()) != H5T_INTEGER) return false;
  std::int64_t v = 0;
  if (H5Aread(attr.get(), H5T_NATIVE_INT64, &v) < 0) return false;
  *out = v;
  return true;
}

bool read_f64_attribute(hid_t object, const char* name, double* out) {
  if (H5Aexists(object, name) <= 0) return false;
  Handle attr(H5Aopen(object, name, H5P_DEFAULT));
  Handle space(attr ? H5Aget_space(attr.get()) : H5I_INVALID_HID);
  if (!space || H5Sget_simple_extent_npoints(space.get()) != 1) return false;
  double v = 0;
  if (H5Aread(attr.get(), H5T_NATIVE_DOUBLE, &v) < 0) return false;
  *out = v;
  return true;
}

std::string describe_attribute(hid_t object, const char* name) {
  const htri_t exists = H5Aexists(object, name);
  if (exists < 0) return "unreadable (corrupt metadata)";
  if (exists == 0) return "missing";
  Handle attr(H5Aopen(object, name, H5P_DEFAULT));
  Handle space(attr ? H5Aget_space(attr.get()) : H5I_INVALID_HID);
  Handle type(attr ? H5Aget_type(attr.get()) : H5I_INVALID_HID);
  if (!space || !type) return "unreadable";
  const hssize_t n = H5Sget_simple_extent_npoints(space.get());
  if (n != 1) return std::to_string(n) + " values, not one";
  switch (H5Tget_class(type.get())) {
    case H5T_INTEGER:
      return "an integer";
    case H5T_FLOAT: {
      double v = 0.0;
      if (H5Aread(attr.get(), H5T_NATIVE_DOUBLE, &v) < 0) return "a floating-point value";
      char text[64];
      std::snprintf(text, sizeof text, "a floating-point value (%.17g)", v);
      return text;
    }
    case H5T_STRING:
      return "a string";
    default:
      return "neither a number nor a string";
  }
}

std::int64_t rows(hid_t dataset) {
  Handle space(H5Dget_space(dataset));
  if (!space) return -1;
  const int rank = H5Sget_simple_extent_ndims(space.get());
  if (rank < 1 || rank > 2) return -1;
  hsize_t dims[2] = {0, 0};
  if (H5Sget_simple_extent_dims(space.get(), dims, nullptr) < 0) return -1;
  return static_cast<std::int64_t>(dims[0]);
}

}  // namespace tissue::record::h5
