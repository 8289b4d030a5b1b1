#!/usr/bin/env bash
# The .deb end to end on this machine (as root): builds it from a Release build in build-package/,
# installs it with apt, checks what it put where, verifies the installed unit with systemd-analyze,
# starts the installed plenopivd as the plenopiv user on the simulated camera with the installed
# config, asks it with the installed `plenopiv status` and `devices`, stops it, starts the installed
# unit under systemd as PID 1 in a container (systemd-nspawn) and runs one pair there, and purges
# the package. Leaves the machine as it found it: the plenopiv user and group and plenopivd's folders
# are removed again when this script made them. Every step prints its wall time.
# PLENOPIV_PACKAGE_BUILD_TYPE: the CMake build type of the package (default Release; RelWithDebInfo
# shares scripts/build.sh's flags, so right after it ccache has every object).
set -euo pipefail
cd "$(dirname "$0")/.."
build=build-package
build_type=${PLENOPIV_PACKAGE_BUILD_TYPE:-Release}
unit=/usr/lib/systemd/system/plenopivd.service
config=/etc/plenopiv/plenopivd.yaml
control_socket=/run/plenopiv/control

fail() {
  echo "test-package: FAIL: $*" >&2
  exit 1
}
step_start=$SECONDS
step() {
  echo "test-package: $1 ($((SECONDS - step_start)) s so far)"
}

[ "$(id -u)" -eq 0 ] || fail "run as root: this installs and purges the package"
if dpkg-query -W -f='${Status}' plenopiv 2>/dev/null | grep -q 'ok installed'; then
  fail "the plenopiv package is installed on this machine already; this test would purge it"
fi
[ ! -e $control_socket ] || fail "$control_socket exists: a plenopivd runs here already"
existed() { if "$@" > /dev/null 2>&1; then echo yes; else echo no; fi; }
user_existed=$(existed getent passwd plenopiv)
group_existed=$(existed getent group plenopiv)
state_existed=$(existed test -e /var/lib/plenopiv)
runtime_existed=$(existed test -e /run/plenopiv)

daemon_pid=""
container_pid=""
cleanup() {
  if [ -n "$daemon_pid" ] && kill "$daemon_pid" 2> /dev/null; then wait "$daemon_pid" || true; fi
  # nspawn answers SIGTERM by powering the container off.
  if [ -n "$container_pid" ] && kill "$container_pid" 2> /dev/null; then wait "$container_pid" || true; fi
  if dpkg-query -W plenopiv > /dev/null 2>&1; then
    DEBIAN_FRONTEND=noninteractive apt-get purge -y -qq plenopiv > /dev/null
  fi
  [ "$state_existed" = yes ] || rm -rf /var/lib/plenopiv
  [ "$runtime_existed" = yes ] || rm -rf /run/plenopiv
  if [ "$user_existed" = no ] && getent passwd plenopiv > /dev/null; then userdel plenopiv; fi
  if [ "$group_existed" = no ] && getent group plenopiv > /dev/null; then groupdel plenopiv; fi
}
trap cleanup EXIT

# 1. The .deb from a Release build (ccache keeps rebuilds short; stripped either way).
launcher=()
command -v ccache > /dev/null && launcher=(-DCMAKE_C_COMPILER_LAUNCHER=ccache -DCMAKE_CXX_COMPILER_LAUNCHER=ccache)
cmake -S . -B $build -G Ninja -DCMAKE_BUILD_TYPE="$build_type" -DCMAKE_INSTALL_PREFIX=/usr -DPLENOPIV_BUILD_TESTS=OFF \
  -DPLENOPIV_BUILD_BENCH=OFF "${launcher[@]}" > /dev/null
cmake --build $build --parallel "$(nproc)"
rm -f $build/plenopiv_*.deb
(cd $build && cpack -G DEB > /dev/null)
deb=$(ls $build/plenopiv_*.deb)
step "built $deb"
depends=$(dpkg-deb -f "$deb" Depends)
for library in libzmq5 libhdf5 libprotobuf libsystemd0 systemd; do
  [[ $depends == *"$library"* ]] || fail "Depends lacks $library (dpkg-shlibdeps): $depends"
done

# 2. Install it as a user would: apt resolves the Depends.
DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends "./$deb" > /dev/null
step "installed"
dpkg-query -W -f='${Conffiles}\n' plenopiv | grep -q "$config" || fail "$config is not a conffile"
for file in /usr/bin/plenopiv /usr/bin/plenopivd $config /etc/plenopiv/camera-fahringer2015.yaml \
  /usr/lib/udev/rules.d/60-plenopiv.rules /usr/lib/sysusers.d/plenopiv.conf /usr/lib/tmpfiles.d/plenopiv.conf \
  /usr/share/bash-completion/completions/plenopiv /usr/share/man/man1/plenopiv.1.gz \
  /usr/share/man/man8/plenopivd.8.gz $unit; do
  [ -f "$file" ] || fail "the package did not install $file"
done
# postinst: the user and group (sysusers.d) and the folders it owns (tmpfiles.d).
id plenopiv > /dev/null || fail "postinst made no plenopiv user"
for folder in /var/lib/plenopiv /run/plenopiv; do
  [ "$(stat -c '%U:%G %a' $folder)" = "plenopiv:plenopiv 750" ] ||
    fail "$folder is $(stat -c '%U:%G %a' $folder), not plenopiv:plenopiv 750"
done

# 3. The installed unit: every path it names exists, and systemd-analyze verify is silent.
exec_start=$(sed -n 's/^ExecStart=//p' $unit)
read -r program _ unit_config <<< "$exec_start"
[ "$program" = /usr/bin/plenopivd ] || fail "the unit starts $program"
[ "$unit_config" = $config ] || fail "the unit reads $unit_config"
documentation=$(sed -n 's|^Documentation=.*file://\([^ ]*\).*|\1|p' $unit)
[ -f "$documentation" ] || fail "the unit's documentation $documentation is not installed"
verify=$(systemd-analyze verify $unit 2>&1) || fail "systemd-analyze verify: $verify"
[ -z "$verify" ] || fail "systemd-analyze verify warns: $verify"
step "unit verified"

# 4. Man pages and completion where man and bash-completion look for them.
man -w plenopivd | grep -q '^/usr/share/man/man8/plenopivd.8.gz$' || fail "man does not find plenopivd(8)"
MANWIDTH=100 man plenopiv-run-start 2> /dev/null | grep -q -- '--config' || fail "man plenopiv-run-start lacks --config"
bash --norc -c 'source /usr/share/bash-completion/bash_completion; _completion_loader plenopiv;
  complete -p plenopiv' | grep -q _plenopiv || fail "bash-completion does not load the installed completion"

# 5. The installed daemon as its user with the installed config (simulation: true, sim://), asked by
# the installed client.
log=$(mktemp)
setpriv --reuid=plenopiv --regid=plenopiv --init-groups -- /usr/bin/plenopivd --config $config > "$log" 2>&1 &
daemon_pid=$!
status=""
for _ in $(seq 120); do
  status=$(/usr/bin/plenopiv status --json 2> /dev/null) && break
  kill -0 $daemon_pid 2> /dev/null || fail "plenopivd exited: $(cat "$log")"
  sleep 0.5
done
[ -n "$status" ] || fail "plenopiv status had no answer in 60 s: $(cat "$log")"
step "plenopivd answers: $status"
grep -q '"state": *"Idle"' <<< "$status" || fail "plenopivd is not idle: $status"
[ "$(stat -c '%U:%G %a' $control_socket)" = "plenopiv:plenopiv 660" ] ||
  fail "$control_socket is $(stat -c '%U:%G %a' $control_socket), not plenopiv:plenopiv 660"
# A member of the plenopiv group controls it too (here the user itself).
setpriv --reuid=plenopiv --regid=plenopiv --init-groups -- /usr/bin/plenopiv status > /dev/null ||
  fail "the plenopiv user cannot ask plenopivd"
/usr/bin/plenopiv devices --json | grep -q '"uri": *"sim://' || fail "plenopiv devices does not list sim://"
kill -TERM $daemon_pid
daemon_rc=0
wait $daemon_pid || daemon_rc=$?
daemon_pid=""
[ $daemon_rc -eq 0 ] || fail "plenopivd exited $daemon_rc on SIGTERM: $(cat "$log")"
rm -f "$log"
step "plenopivd stopped"

# 6. The installed unit under systemd as PID 1, with all its hardening: a container (systemd-nspawn)
# that boots this machine's own /usr and /etc read-only, an empty /var and no network but its own
# loopback, to basic.target. There systemd starts plenopivd.service (Type=notify: READY=1 once the
# sockets are bound), the installed client asks it, a one-pair run on the simulated camera is
# recorded and processed under the unit's sandbox, and systemd stops it cleanly.
command -v systemd-nspawn > /dev/null || fail "systemd-nspawn is missing: Debian package systemd-container (scripts/setup.sh)"
root=$PWD/$build/nspawn-root
rm -rf "$root"
mkdir -p "$root/usr/lib" "$root/etc" "$root/var"
cp /usr/lib/os-release "$root/usr/lib/"  # what nspawn looks for before it binds /usr over it
for link in bin lib lib64 sbin; do [ -L /$link ] && ln -s "$(readlink /$link)" "$root/$link"; done
container_log=$PWD/$build/nspawn.log
systemd-nspawn --quiet --directory="$root" --bind-ro=/usr --bind-ro=/etc --tmpfs=/var --private-network \
  --register=no --keep-unit --boot -- --unit=basic.target > "$container_log" 2>&1 &
container_pid=$!
leader=""
inside() { nsenter --target "$leader" --mount --uts --ipc --net --pid -- "$@"; }
container_fail() {
  [ -z "$leader" ] || inside journalctl -u plenopivd --no-pager -n 50 >&2 || true
  fail "$* (container log: $container_log)"
}
for _ in $(seq 100); do
  leader=$(pgrep -P $container_pid -x systemd || true)
  [ -n "$leader" ] && inside systemctl is-system-running --wait > /dev/null 2>&1 && break
  kill -0 $container_pid 2> /dev/null || fail "the container exited: $(cat "$container_log")"
  sleep 0.3
done
[ "$(inside systemctl is-system-running)" = running ] || container_fail "systemd in the container is not running"
step "systemd is PID 1 in a container"
inside systemctl start plenopivd || container_fail "systemctl start plenopivd failed"
[ "$(inside systemctl is-active plenopivd)" = active ] || container_fail "plenopivd.service is not active"
main_pid=$(inside systemctl show -p MainPID --value plenopivd)
[ "$(inside ps -o user= -p "$main_pid")" = plenopiv ] || container_fail "plenopivd does not run as plenopiv"
# The sandbox is in force: the system call filter (seccomp), no new privileges, no capabilities.
sandbox=$(inside grep -E '^(Seccomp|NoNewPrivs|CapEff):' /proc/"$main_pid"/status | tr -s '\t ' ' ')
for expected in "Seccomp: 2" "NoNewPrivs: 1" "CapEff: 0000000000000000"; do
  grep -qx "$expected" <<< "$sandbox" || container_fail "plenopivd's sandbox lacks '$expected': $sandbox"
done
status=$(inside /usr/bin/plenopiv status --json) || container_fail "plenopiv status had no answer"
grep -q '"state": *"Idle"' <<< "$status" || container_fail "plenopivd is not idle: $status"
step "systemd started plenopivd.service"
inside sh -c 'cat > /var/tmp/one-pair.yaml' << 'YAML'
camera_uri: "sim://?rays=200&ppm=0.05"
pairs: 1
rate_hz: 1
dt_s: 0.001
volume: {x_mm: [-1, 1], y_mm: [-1, 1], z_mm: [-1, 1], voxel_mm: 0.25}
reconstruction: {iterations: 2}
correlation: {passes: [{window: 4, overlap_percent: 50}]}
YAML
inside /usr/bin/plenopiv run start --config /var/tmp/one-pair.yaml > /dev/null || container_fail "the run did not start"
manifest=""
for _ in $(seq 300); do
  manifest=$(inside sh -c 'cat /var/lib/plenopiv/run-*/manifest.json' 2> /dev/null || true)
  grep -q '"state": *"complete"' <<< "$manifest" && break
  sleep 0.5
done
grep -q '"state": *"complete"' <<< "$manifest" || container_fail "the run did not complete in 150 s: $manifest"
inside sh -c 'ls /var/lib/plenopiv/run-*/vectors/*.h5' > /dev/null 2>&1 || container_fail "the run wrote no vectors"
step "a one-pair run recorded and processed under the unit's sandbox"
inside systemctl stop plenopivd
[ "$(inside systemctl show -p Result --value plenopivd)" = success ] || container_fail "plenopivd did not stop cleanly"
[ "$(inside systemctl show -p ExecMainStatus --value plenopivd)" = 0 ] || container_fail "plenopivd exited non-zero"
inside systemctl poweroff
wait $container_pid || fail "the container did not shut down cleanly: $(cat "$container_log")"
container_pid=""
step "systemd stopped plenopivd.service; container shut down"

# 7. Purge: nothing of the package is left.
DEBIAN_FRONTEND=noninteractive apt-get purge -y -qq plenopiv > /dev/null
for path in /usr/bin/plenopivd /etc/plenopiv $unit; do
  [ ! -e $path ] || fail "$path is left after purge"
done
step "purged; passed"
