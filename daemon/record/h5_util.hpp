// Small RAII and error helpers over the HDF5 C API, shared by the session
// writer and the session tools. Internal to tissue_record.
#pragma once

#include <hdf5.h>

#include <cstddef>
#include <cstdint>
#include <string>
#include <utility>
#include <vector>

namespace tissue::record::h5 {

// Owns one hid_t and closes it with the matching H5?close. HDF5 ids leak
// silently when forgotten, and every error path here returns early.
class Handle {
 public:
  Handle() = default;
  explicit Handle(hid_t id) : id_(id) {}
  ~Handle() { reset(); }
  Handle(Handle&& o) noexcept : id_(std::exchange(o.id_, H5I_INVALID_HID)) {}
  Handle& operator=(Handle&& o) noexcept {
    if (this != &o) {
      reset();
      id_ = std::exchange(o.id_, H5I_INVALID_HID);
    }
    return *this;
  }
  Handle(const Handle&) = delete;
  Handle& operator=(const Handle&) = delete;

  hid_t get() const { return id_; }
  bool valid() const { return id_ >= 0; }
  explicit operator bool() const { return valid(); }
  // Closes now; returns false when HDF5 reported a failure (e.g. the final
  // flush of a file hit a full disk).
  bool reset();
  hid_t release() { return std::exchange(id_, H5I_INVALID_HID); }

 private:
  hid_t id_ = H5I_INVALID_HID;
};

// HDF5 prints its error stack to stderr by default: a daemon log and a CLI
// must show our own one-line messages instead. The setting is per thread in
// thread-safe builds, so every public entry point holds one of these; it
// restores the caller's setting on exit.
class QuietErrors {
 public:
  QuietErrors();
  ~QuietErrors();
  QuietErrors(const QuietErrors&) = delete;
  QuietErrors& operator=(const QuietErrors&) = delete;

 private:
  H5E_auto2_t old_func_ = nullptr;
  void* old_data_ = nullptr;
};

// The innermost HDF5 error message(s) of the current thread's error stack,
// e.g. "file write failed: ... errno = 27, error message = 'File too large'".
// Empty when the stack is empty.
std::string last_error();

// "<what>: <last_error()>" — every failure names the HDF5 reason.
std::string describe(const std::string& what);

// Attributes. In SWMR mode only existing ones may be rewritten, in place:
// strings then need their room reserved up front (`stored_bytes`, counting
// the terminating NUL; the value's own size when larger).
void write_string_attribute(hid_t object, const char* name, const std::string& value, std::size_t stored_bytes = 0);
void write_u8_attribute(hid_t object, const char* name, std::uint8_t value);
void write_i64_attribute(hid_t object, const char* name, std::int64_t value);
void write_f64_attribute(hid_t object, const char* name, double value);
// Return false (and leave `out` alone) when the attribute is missing or
// unreadable as one value of the kind: read_i64_attribute reads integer
// attributes only (never a floating-point one truncated: 2.5 is not 2),
// read_f64_attribute floating-point and integer ones.
bool read_string_attribute(hid_t object, const char* name, std::string* out);
bool read_i64_attribute(hid_t object, const char* name, std::int64_t* out);
bool read_f64_attribute(hid_t object, const char* name, double* out);
// What an attribute holds, for an error saying why it could not be read:
// "missing", "a floating-point value (2.5)", "a string", "2 values, not one".
std::string describe_attribute(hid_t object, const char* name);

// Current extent of a dataset's first dimension; -1 when it cannot be read.
std::int64_t rows(hid_t dataset);

}  // namespace tissue::record::h5
