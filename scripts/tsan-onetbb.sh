#!/usr/bin/env bash
# Builds Debian's own oneTBB source (the version libtbb-dev installs) with ThreadSanitizer, through
# oneTBB's TBB_SANITIZE option, and installs it under build-tsan/onetbb/install: the TSan build links
# it (TBB_DIR) so that TSan sees the library's synchronisation between pipeline stages, and oneTBB's
# suspended tasks run on threads instead of switched stacks. Prints the TBB_DIR to use. The source
# comes from bookworm's deb-src through apt (signed index, checksummed files), nothing installed.
set -euo pipefail
cd "$(dirname "$0")/.."
dir=$PWD/build-tsan/onetbb
version=$(dpkg-query -W -f '${Version}' libtbb-dev)
install=$dir/install
if [[ -f $install/version && $(cat "$install/version") == "$version" ]]; then
  echo "$install/lib/cmake/TBB"
  exit 0
fi
rm -rf "$dir"
mkdir -p "$dir/src"
source scripts/private-apt.sh
{
  private_apt "$dir/apt" deb-src bookworm
  (cd "$dir/src" && apt-get "${apt_options[@]}" source -qq "onetbb=$version")
  source_dir=$(find "$dir/src" -mindepth 1 -maxdepth 1 -type d -name 'onetbb-*')
  launcher=()
  command -v ccache > /dev/null && launcher=(-DCMAKE_CXX_COMPILER_LAUNCHER=ccache)
  # The library only (no tests, examples, tbbmalloc or tbbbind: plenopiv links TBB::tbb alone).
  cmake -S "$source_dir" -B "$dir/build" -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo \
    -DCMAKE_C_COMPILER=clang -DCMAKE_CXX_COMPILER=clang++ "${launcher[@]}" -DTBB_SANITIZE=thread \
    -DTBB_TEST=OFF -DTBB_EXAMPLES=OFF -DTBB_STRICT=OFF -DTBBMALLOC_BUILD=OFF -DTBB_DISABLE_HWLOC_AUTOMATIC_SEARCH=ON \
    -DCMAKE_INSTALL_PREFIX="$install"
  cmake --build "$dir/build" --parallel "$(nproc)"
  cmake --install "$dir/build"
} >&2
echo "$version" > "$install/version"
echo "$install/lib/cmake/TBB"
