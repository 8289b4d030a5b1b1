#!/usr/bin/env bash
# Installs the Debian packages plenopiv builds and runs with, if any are missing (idempotent).
# Runs as root, or through sudo; says what it installs.
set -euo pipefail

packages=(
  # toolchain
  g++ cmake ninja-build pkg-config git
  # .ci/run's sanitizer and fuzzing builds: clang with libFuzzer and the sanitizer runtimes,
  # llvm-symbolizer for their stack traces, ccache for the rebuilds
  clang libclang-rt-14-dev llvm ccache
  # the source format (.clang-format; scripts/format.sh)
  clang-format-14
  # design card: camera, USB, GPIO, images, messaging, logging, threads, tests
  libaravis-dev aravis-tools libusb-1.0-0-dev libgpiod-dev gpiod libopencv-dev
  libzmq3-dev cppzmq-dev libprotobuf-dev protobuf-compiler libspdlog-dev libtbb-dev
  libgtest-dev libgmock-dev libbenchmark-dev
  # numerics and files
  libfftw3-dev libsleef-dev libxxhash-dev libhdf5-dev libyaml-cpp-dev libcli11-dev libsystemd-dev libtiff-dev zlib1g-dev
  # preview plots (PLplot, PNG through its cairo driver); exports (NetCDF-4, the zip of NumPy's .npz)
  libplplot-dev plplot-driver-cairo libnetcdf-dev libzip-dev
  # the Python package (clients/python), plots and file checks (Debian's /usr/bin/python3); it is
  # built with setuptools and wheel and installed with pip into a venv, with no index
  python3 python3-numpy python3-zmq python3-protobuf python3-h5py python3-matplotlib python3-xarray
  python3-venv python3-pip python3-setuptools python3-wheel
  # export tests read the files back: NetCDF-4
  python3-netcdf4
  # systemd unit checks; man pages from --help, the bash completion's helpers and its test, the .deb
  # (dpkg-shlibdeps for its Depends, man-db to render the pages; scripts/test-package.sh, which boots
  # systemd as PID 1 in a systemd-nspawn container to start the installed unit)
  systemd systemd-container help2man bash-completion dpkg-dev man-db
  # a real one-node Slurm for `plenopiv slurm` and its tests (scripts/slurm-local.sh)
  slurm-wlm munge
  # bench/oneshot_cli.sh: GNU time (wall, CPU and peak memory of a CLI call), PyYAML
  time python3-yaml
)

missing=()
for p in "${packages[@]}"; do
  if ! dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed"; then
    missing+=("$p")
  fi
done

if [ ${#missing[@]} -eq 0 ]; then
  echo "setup: all ${#packages[@]} Debian packages are installed"
  exit 0
fi

echo "setup: installing ${#missing[@]} Debian packages: ${missing[*]}"
sudo_cmd=()
if [ "$(id -u)" -ne 0 ]; then
  command -v sudo >/dev/null || { echo "setup: not root and no sudo: run as root" >&2; exit 1; }
  sudo_cmd=(sudo)
fi
export DEBIAN_FRONTEND=noninteractive
"${sudo_cmd[@]}" apt-get update -qq
"${sudo_cmd[@]}" apt-get install -y -qq --no-install-recommends "${missing[@]}"
echo "setup: done"
