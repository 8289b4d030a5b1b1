#!/usr/bin/env bash
# The test command: set up, build (every folder but bench/: `bash scripts/build.sh` builds the
# benchmarks, and .ci/run does after this), and run every test but the `slow` ones.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
PLENOPIV_SKIP_BENCH=1 bash scripts/build.sh
cd build
ctest --label-exclude slow --output-on-failure --timeout 600 -j "$(nproc)"
