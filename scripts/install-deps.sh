#!/usr/bin/env bash
# Installs the Debian 12 packages tissued needs, only those missing, so it is
# cheap and safe to run every time (the README commands call it first).
set -euo pipefail

packages=(
  build-essential cmake ninja-build pkg-config git
  libeigen3-dev libcli11-dev libyaml-cpp-dev nlohmann-json3-dev libfmt-dev libspdlog-dev
  libgtest-dev libgmock-dev libbenchmark-dev
  libfastrtps-dev libfastcdr-dev fastddsgen fastdds-tools
  liblcm-dev liblcm-bin libglib2.0-dev
  libhdf5-dev hdf5-tools python3-h5py python3-pip
  libosmesa6-dev libpng-dev
  libboost-dev libsystemd-dev
  clang-format iproute2
  view3dscene xvfb xauth
)

# Python: the LCM module for clients/python and its test (the PyPI wheel
# decodes types from Debian's lcm-gen). Not fatal: only the Python client needs it.
install_python_lcm() {
  python3 -c 'import lcm' 2>/dev/null && return 0
  python3 -m pip install --quiet lcm==1.5.3 2>/dev/null ||
    python3 -m pip install --quiet --break-system-packages lcm==1.5.3 2>/dev/null ||
    echo "install-deps: could not pip-install the Python 'lcm' module; clients/python needs it" >&2
}

missing=()
for p in "${packages[@]}"; do
  if ! dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed"; then
    missing+=("$p")
  fi
done

if [ ${#missing[@]} -eq 0 ]; then
  echo "install-deps: all ${#packages[@]} packages present"
  install_python_lcm
  exit 0
fi

echo "install-deps: installing ${missing[*]}"
sudo_cmd=()
if [ "$(id -u)" -ne 0 ]; then
  command -v sudo >/dev/null || { echo "install-deps: need root (or sudo) to install: ${missing[*]}" >&2; exit 1; }
  sudo_cmd=(sudo)
fi
export DEBIAN_FRONTEND=noninteractive
"${sudo_cmd[@]}" apt-get update -qq
"${sudo_cmd[@]}" apt-get install -y -qq --no-install-recommends "${missing[@]}"
install_python_lcm
