#!/usr/bin/env bash
# Renders a ParaView figure of a reprocessed run (scripts/paraview_figure.py) with pvbatch; without a display it
# starts a virtual one (Xvfb) for the render: Debian's ParaView renders through X.
# Usage: scripts/paraview_figure.sh RUN/reprocessed/series.pvd -o figure.png [--step N]
# Needs Debian's paraview, python3-paraview and (headless) xvfb: apt-get install paraview python3-paraview xvfb
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
command -v pvbatch >/dev/null || { echo "paraview_figure: no pvbatch: apt-get install paraview python3-paraview" >&2; exit 2; }
if [ -n "${DISPLAY:-}" ]; then
  exec pvbatch "$here/paraview_figure.py" "$@"
fi
command -v Xvfb >/dev/null || { echo "paraview_figure: no display and no Xvfb: apt-get install xvfb" >&2; exit 2; }
# Xvfb picks a free display and writes its number to fd 3 once it accepts connections.
ready=$(mktemp -u)
mkfifo "$ready"
Xvfb -displayfd 3 -screen 0 1280x1024x24 -nolisten tcp 3>"$ready" 2>/dev/null &
xvfb=$!
trap 'kill $xvfb 2>/dev/null || true; rm -f "$ready"' EXIT
read -r display <"$ready"
echo "paraview_figure: no display: rendering on Xvfb :$display" >&2
# Debian's pvbatch 5.11 sometimes fails to open a fresh Xvfb display ("bad X server connection") and
# aborts; that one failure is retried, said aloud, at most twice. Any other failure ends the script.
log=$(mktemp)
trap 'kill $xvfb 2>/dev/null || true; rm -f "$ready" "$log"' EXIT
for attempt in 1 2 3; do
  status=0
  DISPLAY=":$display" pvbatch "$here/paraview_figure.py" "$@" >"$log" 2>&1 || status=$?
  if [ $status -eq 0 ] || ! grep -q "bad X server connection" "$log" || [ $attempt -eq 3 ]; then
    grep -v '^ *[0-9]* *0x' "$log" || true
    exit $status
  fi
  echo "paraview_figure: pvbatch could not connect to Xvfb :$display (attempt $attempt of 3); retrying" >&2
done
