#!/usr/bin/env bash
# The main job: set up, build, start plenopivd, start a short run from the thin client, watch
# vector fields arrive, stop the run, and stop the daemon cleanly.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
bash scripts/build.sh >/dev/null
echo "demo: build ready in build/bin"

data_dir="build/demo-data"
mkdir -p "$data_dir"
# Control through a socket file only this user can open (tcp:// control needs CURVE keys).
control="ipc://$PWD/build/demo-control"
publish="tcp://127.0.0.1:${PLENOPIV_DEMO_PUBLISH_PORT:-5556}"
client=(build/bin/plenopiv --endpoint "$control")

# The simulated plenoptic camera renders every pair with the ray tracer (a uniform flow of
# 0.25 mm between the pulses) through a 12-bit sensor's response (shot and read noise, a 20-count
# pedestal, which the daemon measures between the microlens images and takes off); the daemon
# reconstructs and correlates each pair live. The small camera of the paper's sec 5.4 keeps the
# demo quick on two cores.
camera_file="${PLENOPIV_DEMO_CAMERA_FILE:-systemd/config/camera-small.yaml}"
camera="${PLENOPIV_DEMO_CAMERA:-sim://?seed=1&ppm=0.3&dx_mm=0.25&noise=1}"
build/bin/plenopivd --config systemd/config/plenopivd.yaml --control "$control" \
  --publish "$publish" --data-dir "$data_dir" --camera-file "$camera_file" --camera "$camera" --simulation &
daemon=$!
trap 'kill $daemon 2>/dev/null || true' EXIT

# Wait until the daemon answers (the client itself times out after --timeout seconds).
for _ in $(seq 1 50); do
  if "${client[@]}" --timeout 0.2 status >/dev/null 2>&1; then break; fi
  kill -0 $daemon 2>/dev/null || { echo "demo: plenopivd exited" >&2; exit 1; }
done

echo "== plenopiv camera --camera $camera_file"
build/bin/plenopiv camera --camera "$camera_file"
echo "== plenopiv devices"
"${client[@]}" devices
echo "== plenopiv watch --count 4 (subscribed before the run starts)"
build/bin/plenopiv watch --publish "$publish" --count 4 --wait 20 &
watcher=$!
sleep 0.5
echo "== plenopiv run start --config systemd/config/run.yaml"
"${client[@]}" run start --config systemd/config/run.yaml
wait $watcher
echo "== plenopiv status"
"${client[@]}" status
echo "== plenopiv run stop"
"${client[@]}" run stop
for _ in $(seq 1 100); do
  "${client[@]}" status | grep -q "^state          Idle" && break
  sleep 0.1
done
run_dir=$(ls -d "$data_dir"/run-* | tail -1)
echo "== $run_dir"
ls "$run_dir"
grep -m1 '"state"' "$run_dir/manifest.json"
echo "frames on disk: $(ls "$run_dir/frames" | wc -l)"
first=$(ls "$run_dir"/vectors/*.h5 | head -1)
echo "== one vector field, as Python sees it ($first)"
/usr/bin/python3 - "$first" <<'PY'
import sys, h5py
with h5py.File(sys.argv[1], "r") as f:
    g = f["vectors"]
    u = g["u"]
    print("u: shape", u.shape, "(z, y, x),", u.attrs["units"].decode(), "- mean %.3f" % float(u[()].mean()))
    print("axes:", ", ".join("%s %.2f..%.2f mm" % (a, g[a][0], g[a][-1]) for a in "xyz"))
    print("provenance:", ", ".join("%s=%s" % (k, f["provenance"].attrs[k].decode())
                                   for k in ("software", "run", "pair_index", "dt_source")))
PY
cat <<EOF
== where the results are
  $run_dir: run.yaml, camera.yaml, process.yaml, manifest.json (every pair, its frames and dt),
  frames/pair-<n>-A.tif and -B.tif (raw 16-bit), vectors/pair-<n>.h5 (u, v, w in m/s, vorticity,
  flags, x/y/z in mm, provenance), statistics.h5 (mean and RMS fluctuation).
  Reprocessed offline into .h5 and .vti with a ParaView series:
    build/bin/plenopiv process --run $run_dir    # then open $run_dir/reprocessed/series.pvd in ParaView
  In Python (xarray): plenopiv.open("$run_dir") from the package in clients/python;
  README.md, "From a recorded run to a ParaView figure", walks through both.
EOF

kill -TERM $daemon
wait $daemon
trap - EXIT
echo "demo: plenopivd stopped cleanly"
