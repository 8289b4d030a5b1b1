#!/usr/bin/env bash
# Formats the C++ sources with clang-format-14 (.clang-format); --check only reports, failing when a
# file is not formatted (as .ci/run does).
set -euo pipefail
cd "$(dirname "$0")/.."
mode=(-i)
[[ "${1:-}" == "--check" ]] && mode=(--dry-run -Werror)
git ls-files '*.cpp' '*.hpp' '*.h' '*.cc' | xargs clang-format-14 "${mode[@]}"
