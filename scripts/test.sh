#!/usr/bin/env bash
# The test command: set up, build, and run every test but the `slow` ones.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
bash scripts/build.sh
cd build
ctest --label-exclude slow --output-on-failure --timeout 600 -j "$(nproc)"
