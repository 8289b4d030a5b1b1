#!/usr/bin/env bash
# #21's 5-iteration volume: run-paper.yaml's MART (5 accelerated iterations at mu 1, pruned below
# 1e-2 of each depth slice's peak) on the paper camera's 300 x 200 x 200 voxels of 0.125 mm, one
# 0.5 ppm frame, each repeat in a fresh process: its first frame as a one-shot call meets it (fresh
# memory), then the same frame in the kept workspace as a run's steady state does.
#   bash bench/recon_volume.sh [REPEATS]   (default 3)
# Prints bench_recon's bench=recon_prune lines, one per repeat, with repeat=K appended.
set -euo pipefail
cd "$(dirname "$0")/.."
repeats=${1:-3}
for ((k = 1; k <= repeats; ++k)); do
  build/bin/bench_recon prune paper 0.5 5 1 nesterov slice-1e-2-local-5e-2 | sed "/^bench=recon_prune case=/s/\$/ repeat=$k/"
done
