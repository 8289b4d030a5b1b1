#!/usr/bin/env bash
# Reprocessing a recorded run on a real one-node Slurm (scripts/slurm-local.sh) against a local
# `plenopiv process --run`: wall time per pair and the overhead of sharding (N array tasks + merge).
#   bash bench/slurm_sharding.sh [PAIRS] [REPEATS]     (defaults 16 pairs, 3 repeats; needs root)
# Records PAIRS pairs on the small camera with plenopivd's simulated camera (systemd/config/run.yaml),
# then reprocesses them with the offline settings (systemd/config/process.yaml): locally with one
# job, and as 1, 2 and 4 shards of one CPU each; prints median wall times and ratios.
set -euo pipefail
cd "$(dirname "$0")/.."
pairs=${1:-16}
repeats=${2:-3}
work="$PWD/build/bench-slurm"
rm -rf "$work"
mkdir -p "$work"
plenopiv="$PWD/build/bin/plenopiv"

# The cluster.
bash scripts/slurm-local.sh start "$work/cluster" >/dev/null
export SLURM_CONF="$work/cluster/slurm.conf"
trap 'kill $daemon 2>/dev/null || true; bash scripts/slurm-local.sh stop "$work/cluster" >/dev/null' EXIT

# The run: plenopivd on the simulated camera, PAIRS pairs.
control="ipc://$work/control"
build/bin/plenopivd --config systemd/config/plenopivd.yaml --control "$control" --publish "tcp://127.0.0.1:5599" \
  --data-dir "$work/data" --camera-file systemd/config/camera-small.yaml \
  --camera "sim://?seed=1&ppm=0.3&dx_mm=0.25" --simulation >"$work/plenopivd.log" 2>&1 &
daemon=$!
for _ in $(seq 50); do "$plenopiv" --endpoint "$control" --timeout 0.2 status >/dev/null 2>&1 && break; done
sed "s/^pairs: .*/pairs: $pairs/" systemd/config/run.yaml >"$work/run.yaml"
"$plenopiv" --endpoint "$control" run start --config "$work/run.yaml" >/dev/null
for _ in $(seq 600); do
  "$plenopiv" --endpoint "$control" status | grep -q "^state          Idle" && break
  sleep 0.5
done
kill -TERM $daemon; wait $daemon || true
run=$(ls -d "$work"/data/run-* | tail -1)
echo "run $run: $(grep -c '"frame_a"' "$run/manifest.json") pairs; offline settings systemd/config/process.yaml"

now() { date +%s.%N; }
since() { awk -v a="$(now)" -v b="$1" 'BEGIN { print a - b }'; }
ratio() { awk -v a="$1" -v b="$2" 'BEGIN { print a / b }'; }
source bench/stats.sh  # median
wait_jobs() {
  while [ -n "$(squeue --noheader --jobs="$1" 2>/dev/null)" ]; do sleep 0.2; done
}

for r in $(seq "$repeats"); do
  out="$work/local-$r"
  t0=$(now)
  "$plenopiv" process --run "$run" --config systemd/config/process.yaml -o "$out" >/dev/null 2>&1
  since "$t0" >>"$work/local.times"
  for n in 1 2 4; do
    out="$work/shards$n-$r"
    t0=$(now)
    jobs=$("$plenopiv" slurm submit --run "$run" --config systemd/config/process.yaml -o "$out" --shards "$n" \
      --cpus 1 2>/dev/null | tr ' ' ',')
    wait_jobs "$jobs"
    [ -f "$out/statistics.h5" ] || { echo "bench: shards $n: no merge (see $out/slurm)" >&2; exit 1; }
    since "$t0" >>"$work/shards$n.times"
  done
done

local_s=$(median <"$work/local.times")
row_wall="| wall s (s per pair) | $(printf '%.1f (%.2f)' "$local_s" "$(ratio "$local_s" "$pairs")")"
row_ratio="| against local | 1.00"
for n in 1 2 4; do
  s=$(median <"$work/shards$n.times")
  row_wall+=" | $(printf '%.1f (%.2f)' "$s" "$(ratio "$s" "$pairs")")"
  row_ratio+=" | $(printf '%.2f' "$(ratio "$s" "$local_s")")"
done
merge_s=$( { t0=$(now); "$plenopiv" process --run "$run" --config systemd/config/process.yaml -o "$work/local-1" \
  --merge >/dev/null 2>&1; since "$t0"; } )
echo
echo "| median of $repeats | local | 1 shard | 2 shards | 4 shards |"
echo "|---|---|---|---|---|"
echo "$row_wall |"
echo "$row_ratio |"
echo "merge alone: $(printf '%.1f' "$merge_s") s; load $(cut -d' ' -f1-3 /proc/loadavg)"
