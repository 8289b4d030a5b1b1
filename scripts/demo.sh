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
control="tcp://127.0.0.1:${PLENOPIV_DEMO_CONTROL_PORT:-5555}"
publish="tcp://127.0.0.1:${PLENOPIV_DEMO_PUBLISH_PORT:-5556}"
client=(build/bin/plenopiv --endpoint "$control")

# Until the simulated camera (sim://) and the reconstruction/correlation stage are built into
# plenopivd, the demo runs the same daemon built with the test camera (test://) and a test
# processing stage whose vector fields carry u = pair index (tests/daemon/plenopivd_test_build.cpp).
daemon_bin="${PLENOPIV_DEMO_DAEMON:-build/bin/plenopivd-testcam}"
camera="${PLENOPIV_DEMO_CAMERA:-test://}"
"$daemon_bin" --config systemd/config/plenopivd.yaml --control "$control" \
  --publish "$publish" --data-dir "$data_dir" --camera "$camera" &
daemon=$!
trap 'kill $daemon 2>/dev/null || true' EXIT

# Wait until the daemon answers (the client itself times out after --timeout seconds).
for _ in $(seq 1 50); do
  if "${client[@]}" --timeout 0.2 status >/dev/null 2>&1; then break; fi
  kill -0 $daemon 2>/dev/null || { echo "demo: plenopivd exited" >&2; exit 1; }
done

echo "== plenopiv camera systemd/config/camera-fahringer2015.yaml"
build/bin/plenopiv camera systemd/config/camera-fahringer2015.yaml
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

kill -TERM $daemon
wait $daemon
trap - EXIT
echo "demo: plenopivd stopped cleanly"
