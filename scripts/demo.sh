#!/usr/bin/env bash
# The main job: set up, build, start plenopivd on the simulated camera, drive it from the thin
# client, show what arrives, and stop the daemon cleanly.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
bash scripts/build.sh >/dev/null
echo "demo: build ready in build/bin"

data_dir="build/demo-data"
mkdir -p "$data_dir"
control="tcp://127.0.0.1:${PLENOPIV_DEMO_CONTROL_PORT:-5555}"
publish="tcp://127.0.0.1:${PLENOPIV_DEMO_PUBLISH_PORT:-5556}"

build/bin/plenopivd --config systemd/config/plenopivd.yaml --control "$control" \
  --publish "$publish" --data-dir "$data_dir" &
daemon=$!
trap 'kill $daemon 2>/dev/null || true' EXIT

# Wait until the daemon answers (the client itself times out after --timeout seconds).
for _ in $(seq 1 50); do
  if build/bin/plenopiv --endpoint "$control" --timeout 0.2 status >/dev/null 2>&1; then break; fi
  kill -0 $daemon 2>/dev/null || { echo "demo: plenopivd exited" >&2; exit 1; }
done

echo "== plenopiv camera systemd/config/camera-fahringer2015.yaml"
build/bin/plenopiv camera systemd/config/camera-fahringer2015.yaml
echo "== plenopiv devices"
build/bin/plenopiv --endpoint "$control" devices
echo "== plenopiv status"
build/bin/plenopiv --endpoint "$control" status

kill -TERM $daemon
wait $daemon
trap - EXIT
echo "demo: plenopivd stopped cleanly"
