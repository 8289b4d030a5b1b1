#!/usr/bin/env bash
# Configures and builds plenopiv in build/ (binaries in build/bin). Extra args go to cmake configure.
# Compiles through ccache when it is installed (scripts/setup.sh installs it): the package build
# (scripts/test-package.sh) and rebuilds after a clean then take their objects from it.
set -euo pipefail
cd "$(dirname "$0")/.."
launcher=()
command -v ccache > /dev/null && launcher=(-DCMAKE_C_COMPILER_LAUNCHER=ccache -DCMAKE_CXX_COMPILER_LAUNCHER=ccache)
cmake -S . -B build -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo "${launcher[@]}" "$@"
cmake --build build --parallel "$(nproc)"
