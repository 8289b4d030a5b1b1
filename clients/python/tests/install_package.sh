#!/usr/bin/env bash
# Installs the plenopiv Python package from a clean copy of clients/python into a fresh venv (Debian's
# python3 with its system site packages, no index): what the Python tests then import.
# Usage: install_package.sh SOURCE_DIR WORK_DIR  (the venv: WORK_DIR/venv)
set -euo pipefail
source_dir=$(cd "$1" && pwd)
work_dir=$2
rm -rf "$work_dir"
mkdir -p "$work_dir/src"
# A clean copy: no build/ or egg-info left by an earlier in-tree build.
cp -r "$source_dir/pyproject.toml" "$source_dir/setup.py" "$source_dir/README.md" "$source_dir/plenopiv" "$work_dir/src/"
# Without its own pip: Debian's pip (python3-pip) installs into it, building with Debian's setuptools.
/usr/bin/python3 -m venv --system-site-packages --without-pip "$work_dir/venv"
PLENOPIV_PROTO_DIR="$source_dir/../../proto" \
  /usr/bin/python3 -m pip --python "$work_dir/venv/bin/python" install --quiet --no-build-isolation --no-index --disable-pip-version-check "$work_dir/src"
"$work_dir/venv/bin/python" -c "import plenopiv, plenopiv.plenopiv_pb2; print('installed', plenopiv.__file__)"
