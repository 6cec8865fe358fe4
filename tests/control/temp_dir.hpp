// The shared scratch directory (tests/support/process_support.hpp), under the
// control suites' name.
#pragma once

#include "support/process_support.hpp"

namespace tissue::control::testing {

using tissue::testing::TempDir;

}  // namespace tissue::control::testing
