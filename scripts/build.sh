#!/usr/bin/env bash
# Configures and builds plenopiv in build/ (binaries in build/bin). Extra args go to cmake configure.
# PLENOPIV_SKIP_BENCH=1 builds every folder but bench/ (the test command's build: no test runs a
# benchmark). Compiles through ccache when it is installed (scripts/setup.sh installs it): the
# package build (scripts/test-package.sh) and rebuilds after a clean then take their objects from it.
set -euo pipefail
cd "$(dirname "$0")/.."
launcher=()
command -v ccache > /dev/null && launcher=(-DCMAKE_C_COMPILER_LAUNCHER=ccache -DCMAKE_CXX_COMPILER_LAUNCHER=ccache)
cmake -S . -B build -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo "${launcher[@]}" "$@"
targets=(all)
if [ "${PLENOPIV_SKIP_BENCH:-0}" = 1 ]; then
  # The folders' targets that make up `all` (ninja's `<folder>/all`, as CMake generated them), but bench/'s.
  mapfile -t targets < <(ninja -C build -t query all | sed -n '/input:/,/outputs:/p' | grep -E '^ +[^ ]+/all$' |
    tr -d ' ' | grep -vx 'bench/all')
  [ "${#targets[@]}" -gt 0 ] || {
    echo "scripts/build.sh: no folder targets found in build/build.ninja" >&2
    exit 1
  }
fi
cmake --build build --parallel "$(nproc)" --target "${targets[@]}"
