#!/usr/bin/env bash
# The paper ring through sensors other than the simulator's one count per ray, with each frame's
# black level taken off (reconstruction.black_level: between_images) or left on (none): one
# bench_e2e full run per case, one after another, each printing its bench=e2e header line (sensor=,
# black_level=, black_level_a=, noise_threshold=) before its rows.
#   bash bench/sensor_cases.sh CASE... -- BENCH_E2E_FLAGS...
# CASE: SENSOR/BLACK_LEVEL[/EXTRA]: SENSOR `clean` (one count per ray) or bench_e2e's --sensor-noise
# E,R,O (photo-electrons per ray, read noise in electrons, pedestal in counts); BLACK_LEVEL
# between_images or none; EXTRA more bench_e2e flags for that case, words joined by '+' (e.g.
# --noise-threshold+28). BENCH_E2E_FLAGS: the settings every case shares (bench_tables passes
# run-paper.yaml's).
set -euo pipefail
cd "$(dirname "$0")/.."
cases=()
while [[ $# -gt 0 && $1 != "--" ]]; do
  cases+=("$1")
  shift
done
if [[ $# -eq 0 || ${#cases[@]} -eq 0 ]]; then
  echo "usage: bash bench/sensor_cases.sh CASE... -- BENCH_E2E_FLAGS..." >&2
  exit 2
fi
shift
for c in "${cases[@]}"; do
  IFS=/ read -r sensor black extra <<<"$c"
  args=(--black-level "$black")
  [[ $sensor != clean ]] && args+=(--sensor-noise "$sensor")
  [[ -n ${extra:-} ]] && read -r -a more <<<"${extra//+/ }" && args+=("${more[@]}")
  build/bin/bench_e2e full --no-sweep "$@" "${args[@]}"
done
