#!/usr/bin/env bash
# Writes the seed corpus of the fuzz targets (tests/fuzz/corpus/<target>/) with the project's own
# programs: a real plenopivd run on the seed camera (manifest, frames, vector fields), `plenopiv
# simulate`/`calibrate`/`reconstruct`/`refocus`, protoc for control messages, and Debian's Python
# (PIL, h5py) for the variants our writers do not make (8-bit, compressed, chunked). Text seeds
# (configs, URIs, mini-languages) are written here too. Rerun after a file format changes:
#   bash tests/fuzz/make_seeds.sh [build/bin]
set -euo pipefail
root=$(cd "$(dirname "$0")/../.." && pwd)
bin=$(cd "${1:-$root/build/bin}" && pwd)
out=$root/tests/fuzz/corpus
work=$(mktemp -d)
daemon_pid=
cleanup() {
  [ -n "$daemon_pid" ] && kill "$daemon_pid" 2>/dev/null || true
  rm -rf "$work"
}
trap cleanup EXIT
py=/usr/bin/python3

rm -rf "$out"
mkdir -p "$out"/{control_request,run_config,daemon_config,run_manifest,camera_file,tiff,hdf5_volume,hdf5_vectors,calibration_file,device_uri,passes,depths}

# The seed camera (tests/fuzz/seed_camera.hpp holds the same text): 85 x 85 px, 5 x 5 lenses.
cat > "$work/camera.yaml" <<'EOF'
sensor:    {width_px: 85, height_px: 85, pixel_pitch_mm: 0.0074}
microlens: {pitch_mm: 0.125, focal_length_mm: 0.5, count_x: 5, count_y: 5, layout: rect}
main_lens: {focal_length_mm: 50, f_number: 2, magnification: -1}
EOF
cat > "$work/run.yaml" <<'EOF'
rate_hz: 10
dt_s: 0.0001
volume: {x_mm: [-0.25, 0.25], y_mm: [-0.25, 0.25], z_mm: [-0.5, 0.5], voxel_mm: 0.125}
reconstruction: {iterations: 2}
correlation: {passes: [{window: 4, overlap_percent: 50}]}
EOF

# A real run: three pairs recorded and processed.
"$bin/plenopivd" --simulation --camera-file "$work/camera.yaml" --camera "sim://?rays=200&ppm=0.5" \
  --control "ipc://$work/ctl" --publish "ipc://$work/pub" --data-dir "$work/data" > "$work/daemon.log" 2>&1 &
daemon_pid=$!
for _ in $(seq 50); do "$bin/plenopiv" --endpoint "ipc://$work/ctl" --timeout 1 status > /dev/null 2>&1 && break; sleep 0.2; done
"$bin/plenopiv" --endpoint "ipc://$work/ctl" run start --config "$work/run.yaml" --pairs 3 > /dev/null
for _ in $(seq 100); do
  "$bin/plenopiv" --endpoint "ipc://$work/ctl" status | grep -q "^state *Idle" && break
  sleep 0.2
done
kill -TERM "$daemon_pid"; wait "$daemon_pid" || true; daemon_pid=
run=$(echo "$work"/data/run-*)

# control_request: one serialized plenopiv.msg.Request per file.
encode() { protoc --proto_path="$root/proto" --encode=plenopiv.msg.Request plenopiv.proto > "$out/control_request/$1"; }
echo 'id: 1 status {}' | encode status
echo 'id: 2 stop_run {}' | encode stop_run
echo 'id: 3 list_devices {}' | encode list_devices
echo 'id: 4 calibrate { frame_count: 1 camera_uri: "test://" }' | encode calibrate
$py - "$work/run.yaml" <<'EOF' | encode start_run_sim
import sys
print('id: 5 start_run { pair_count: 2 config_yaml: "%s" }' % open(sys.argv[1]).read().replace('"', '\\"').replace('\n', '\\n'))
EOF
$py - "$work/run.yaml" <<'EOF' | encode start_run_test
import sys
text = open(sys.argv[1]).read() + 'camera_uri: "test://?lose=3&incomplete=4"\n'
print('id: 6 start_run { pair_count: 4 config_yaml: "%s" }' % text.replace('"', '\\"').replace('\n', '\\n'))
EOF
printf '' > "$out/control_request/empty"

# run_config and daemon_config: the shipped files and short variants.
cp "$root"/systemd/config/run.yaml "$root"/systemd/config/run-paper.yaml "$root"/systemd/config/process-paper.yaml \
  "$out/run_config/"
cp "$work/run.yaml" "$out/run_config/seed-camera.yaml"
cp "$run/process.yaml" "$out/run_config/process.yaml"
cat > "$out/run_config/everything.yaml" <<'EOF'
camera_uri: "sim://?seed=2&ppm=0.2&flow=ring&rays=100"
trigger_uri: "sim://?clock=virtual"
pairs: 5
duration_s: 2
rate_hz: 5
dt_s: 0.0002
volume: {x_mm: [-1, 1], y_mm: [-1, 1], z_mm: [-2, 2], voxel_mm: 0.25, depth_guard_mm: 0.5}
reconstruction: {iterations: 3, mu: 0.5, start: mlos, noise_threshold: 2, angular_sampling: 1, pixel_binning: 1}
correlation:
  passes: [{window: [16, 16, 32], overlap_percent: 50}, {window: 8, overlap_percent: 75, depth_margin: 2}]
  median: {threshold: 2, epsilon_voxel: 0.1, radius: 2}
  final_smoothing: 1
  spectral_whitening: 0.5
  whitened_peak_sigma_voxel: [1, 1, 2]
publish_volumes: true
max_pairs_in_flight: 2
live_queue: 4
EOF
cp "$root"/systemd/config/plenopivd.yaml "$out/daemon_config/"
cat > "$out/daemon_config/curve.yaml" <<'EOF'
control_endpoint: tcp://127.0.0.1:5555
publish_endpoint: tcp://*:5556
curve: {server_certificate: keys/plenopivd.key_secret, authorized_clients: keys/clients, publish: true}
simulation: true
data_dir: /tmp/plenopiv-data
camera_file: camera.yaml
calibration_file: cal.h5
camera_uri: "sim://?seed=1"
trigger_uri: "gpiod://gpiochip0?flashlamp1=17&qswitch1=18&camera=27"
log_level: debug
publish_high_water_mark: 8
timing:
  flashlamp_to_qswitch_s: 0.00018
  camera_pretrigger_s: 0.00001
  laser_max_rate_hz: 15
EOF

# run_manifest: the run's own manifest, and the same run as a crash would leave it.
cp "$run/manifest.json" "$out/run_manifest/complete.json"
sed 's/"state": *"complete"/"state": "recording"/' "$run/manifest.json" > "$out/run_manifest/recording.json"
# The same run cut to its first pair, whose files the fuzz target's folder holds (read through).
$py - "$run/manifest.json" "$out/run_manifest/one-pair.json" <<'EOF'
import json, sys
m = json.load(open(sys.argv[1]))
m["pairs"] = m["pairs"][:1]
json.dump(m, open(sys.argv[2], "w"), indent=1)
EOF

# camera_file
cp "$work/camera.yaml" "$out/camera_file/seed.yaml"
cp "$root"/systemd/config/camera-*.yaml "$out/camera_file/"
sed 's/layout: rect/layout: hex/' "$work/camera.yaml" > "$out/camera_file/hex.yaml"

# tiff: recorded frames (16-bit), a float stack (refocus), and 8-bit and compressed variants.
cp "$run/frames/pair-000000-A.tif" "$out/tiff/frame-16bit.tif"
"$bin/plenopiv" simulate calibration --camera "$work/camera.yaml" -o "$work/cal.tif" > /dev/null 2>&1
"$bin/plenopiv" simulate white --camera "$work/camera.yaml" -o "$work/white.tif" > /dev/null 2>&1
"$bin/plenopiv" calibrate --camera "$work/camera.yaml" --calibration-image "$work/cal.tif" --white "$work/white.tif" \
  -o "$work/cal.h5" > /dev/null
"$bin/plenopiv" refocus --camera "$work/camera.yaml" --calibration "$work/cal.h5" "$run/frames/pair-000000-A.tif" \
  --z -1:1:1 -o "$work/stack.tif" > /dev/null 2>&1
cp "$work/stack.tif" "$out/tiff/stack-float.tif"
$py - "$run/frames/pair-000000-A.tif" "$out/tiff" <<'EOF'
import sys
from PIL import Image
src, out = sys.argv[1], sys.argv[2]
image = Image.open(src)
small = image.crop((0, 0, 16, 12))
small.save(out + "/small-16bit.tif")
small.save(out + "/small-16bit-lzw.tif", compression="tiff_lzw")
small.save(out + "/small-16bit-deflate.tif", compression="tiff_adobe_deflate")
Image.eval(image.convert("L"), lambda v: v).crop((0, 0, 16, 12)).save(out + "/small-8bit.tif")
small.save(out + "/small-16bit-packbits.tif", compression="packbits")
EOF

# hdf5_volume, hdf5_vectors, calibration_file: files our writers made, and chunked variants.
"$bin/plenopiv" reconstruct "$work/camera.yaml" "$run/frames/pair-000000-A.tif" \
  --extent -0.25 0.25 -0.25 0.25 -0.5 0.5 --iterations 1 -o "$work/volume.h5" > /dev/null 2>&1
cp "$work/volume.h5" "$out/hdf5_volume/volume.h5"
cp "$run/vectors/pair-000000.h5" "$out/hdf5_vectors/vectors.h5"
cp "$run/statistics.h5" "$out/hdf5_vectors/statistics.h5"
cp "$work/cal.h5" "$out/calibration_file/calibration.h5"
$py - "$out" <<'EOF'
import sys, h5py
out = sys.argv[1]
def rewrite(src, dst, **options):
    with h5py.File(src, "r") as a, h5py.File(dst, "w") as b:
        def copy(name, obj):
            if isinstance(obj, h5py.Dataset):
                b.create_dataset(name, data=obj[()], **(options if obj.ndim > 0 else {}))
            else:
                b.require_group(name)
            for k, v in obj.attrs.items():
                b[name].attrs[k] = v
        a.visititems(copy)
        for k, v in a.attrs.items():
            b.attrs[k] = v
rewrite(out + "/hdf5_volume/volume.h5", out + "/hdf5_volume/volume-chunked-gzip.h5", chunks=True, compression="gzip")
rewrite(out + "/hdf5_vectors/vectors.h5", out + "/hdf5_vectors/vectors-chunked-gzip.h5", chunks=True,
        compression="gzip", shuffle=True)
EOF

# device_uri, passes, depths: one string per file.
i=0
while IFS= read -r uri; do
  printf '%s' "$uri" > "$out/device_uri/uri-$((i++))"
done <<'EOF'
sim://?seed=1
sim://?seed=3&ppm=0.2&flow=ring&dx_mm=0.1&rays=100&noise=1&tap_offset=30&brightness_spread=0.5&readout_ms=5&flow_dt_us=100
sim://?flow=rotation&angle_deg=2&drop_every=3&incomplete_every=5&disconnect_after=7&fail_after=9
sim://?flow=shear&shear_per_mm=0.01&depth_mm=4&voxel_mm=0.125&array_rotation_rad=0.01
sim://?clock=virtual&uncertainty_us=5
aravis://127.0.0.1?profile=aravis-fake&packet_size=8000&socket_buffer=8388608&reconnect_s=0.5
aravis://Fake-GV01?profile=jai-piv&buffers=32&resend=off
gpiod://gpiochip0?flashlamp1=17&qswitch1=18&flashlamp2=19&qswitch2=20&camera=27&qsync=22
gpiod://gpiochip1?gate=5&camera=6
test://?lose=3,7&incomplete=4&input=none
EOF
i=0
for passes in "32@50,16@50+4,16x16x32@75" "16@75" "8x8x16@0+2" "64@87.5,32@50"; do
  printf '%s' "$passes" > "$out/passes/passes-$((i++))"
done
i=0
for depths in "-10:10:1" "0:1:0.25" "-2.5,0,2.5" "1e-3"; do
  printf '%s' "$depths" > "$out/depths/depths-$((i++))"
done

du -sh "$out"/* | sort -k2
