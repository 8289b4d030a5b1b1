#!/usr/bin/env bash
# One paper-scale pair through `plenopiv process`, as a user runs it once: reading the TIFFs, the
# weight tables built (an empty cache folder) or read back (the same folder again), MART and the
# correlation, writing the HDF5, .vti and PNG; on a lens array rotated 0.1 deg (the frames are
# resampled onto an axis-aligned lattice, as for any calibrated camera) and on the camera file's.
#   bash bench/oneshot_cli.sh [REPEATS] [CONFIG]   (default 3: medians of the cached calls;
#                                                   systemd/config/run-paper.yaml)
# Everything through the CLI: `plenopiv simulate` renders the white, calibration and pair images
# (the paper's ring vortex at 0.5 ppm in run-paper.yaml's box), `plenopiv calibrate` measures the
# rotated array, and run-paper.yaml's dt_s, volume, reconstruction and correlation are the
# processing spec (or CONFIG's: another config of the paper's box, e.g. process-paper.yaml). Prints
# bench=oneshot lines (key=value): wall and CPU seconds, peak memory, and the voxel updates MART
# skipped, per array and cache state (built: the cache folder empty, so the weight tables, and
# the depth response where CONFIG asks for one, are made).
set -euo pipefail
cd "$(dirname "$0")/.."
repeats=${1:-3}
config=${2:-systemd/config/run-paper.yaml}
work="$PWD/build/bench-oneshot"
rm -rf "$work"
mkdir -p "$work"
plenopiv="$PWD/build/bin/plenopiv"
camera=systemd/config/camera-fahringer2015.yaml
rotation_rad=0.001745329 # 0.1 deg

/usr/bin/python3 - "$work/process.yaml" "$config" <<'EOF'
import sys, yaml
run = yaml.safe_load(open(sys.argv[2]))
yaml.safe_dump({k: run[k] for k in ("dt_s", "volume", "reconstruction", "correlation")}, open(sys.argv[1], "w"))
EOF

for array in nominal rotated; do
  rad=0
  [ "$array" = rotated ] && rad=$rotation_rad
  "$plenopiv" simulate pair --camera "$camera" -o "$work/$array" --ppm 0.5 --ring-vortex 0.125 --seed 2015 \
    --box -18.75 18.75 -12.5 12.5 -12.5 12.5 --array-rotation-rad "$rad" >/dev/null 2>&1
done
"$plenopiv" simulate white --camera "$camera" -o "$work/white.tif" --array-rotation-rad "$rotation_rad" >/dev/null 2>&1
"$plenopiv" simulate calibration --camera "$camera" -o "$work/calibration.tif" --array-rotation-rad "$rotation_rad" \
  >/dev/null 2>&1
"$plenopiv" calibrate --camera "$camera" --white "$work/white.tif" --calibration-image "$work/calibration.tif" \
  -o "$work/calibration.h5" >/dev/null 2>&1

source bench/stats.sh  # median

# One call: prints "wall_s cpu_s peak_gb skipped_a skipped_b" (skipped: the CLI's own report).
one_call() {
  local array=$1 cache=$2 log=$work/call.log
  local source=(--nominal)
  [ "$array" = rotated ] && source=(--calibration "$work/calibration.h5")
  /usr/bin/time -f "time %e %U %S %M" "$plenopiv" process --camera "$camera" -c "$work/process.yaml" "${source[@]}" \
    --cache-dir "$cache" "$work/$array/frame_A.tif" "$work/$array/frame_B.tif" -o "$work/$array/field.h5" \
    >"$log" 2>&1 || { cat "$log" >&2; exit 1; }
  awk '/^time / { printf "%s %.2f %.3f ", $2, $3 + $4, $5 / 1048576 }' "$log"
  sed -n 's/.*reconstruct A .*(voxel updates skipped \([0-9.]*\) %).*(skipped \([0-9.]*\) %).*/\1 \2/p' "$log"
}

for array in nominal rotated; do
  cache="$work/cache-$array"
  read -r wall cpu peak skip_a skip_b <<<"$(one_call "$array" "$cache")"
  echo "bench=oneshot array=$array cache=built wall_s=$wall cpu_s=$cpu peak_rss_gb=$peak updates_skipped_a=$skip_a" \
    "updates_skipped_b=$skip_b"
  : >"$work/wall" && : >"$work/cpu" && : >"$work/peak"
  for _ in $(seq "$repeats"); do
    read -r wall cpu peak skip_a skip_b <<<"$(one_call "$array" "$cache")"
    echo "$wall" >>"$work/wall" && echo "$cpu" >>"$work/cpu" && echo "$peak" >>"$work/peak"
  done
  echo "bench=oneshot array=$array cache=read repeats=$repeats wall_s=$(median <"$work/wall")" \
    "wall_min_s=$(sort -g "$work/wall" | head -1) wall_max_s=$(sort -g "$work/wall" | tail -1)" \
    "cpu_s=$(median <"$work/cpu") peak_rss_gb=$(median <"$work/peak") updates_skipped_a=$skip_a" \
    "updates_skipped_b=$skip_b"
done
