#!/usr/bin/env bash
# libgpiod v2 (2.x, Debian 13's libgpiod-dev) builds and runs the gpiod:// trigger's chip layer too,
# on a Debian 12 machine: the v2 packages are fetched from Debian's trixie suite into build-gpiod2/
# (extracted, nothing installed), plenopiv is configured against them (CMake must pick
# gpio_chip_v2.cpp), the trigger's gpiod sources are compiled with the project's flags, and a small
# program linked with the v2 library opens a chip that does not exist and reports the library's
# version. The v1 build is the main one (scripts/build.sh).
set -euo pipefail
cd "$(dirname "$0")/.."
dir=$PWD/build-gpiod2
deps=$dir/libgpiod2
rm -rf "$dir"
mkdir -p "$deps/root"
source scripts/private-apt.sh
private_apt "$deps/apt" deb trixie
(cd "$deps" && apt-get "${apt_options[@]}" download -qq libgpiod-dev libgpiod3)
for deb in "$deps"/*.deb; do dpkg-deb -x "$deb" "$deps/root"; done
libdir=$deps/root/usr/lib/x86_64-linux-gnu

# pkg-config finds libgpiod's .pc file here first, its prefix moved to the extracted tree.
sed -i "s|^prefix=/usr$|prefix=$deps/root/usr|" "$libdir/pkgconfig/libgpiod.pc"
export PKG_CONFIG_PATH=$libdir/pkgconfig
cmake -S . -B "$dir" -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo -DPLENOPIV_BUILD_BENCH=OFF > "$dir/configure.log"
grep -q "found libgpiod>=1.6 2\." "$dir/configure.log" || { cat "$dir/configure.log"; echo "libgpiod v2 not found"; exit 1; }
objects=()
for source in gpio_chip_v2 gpiod_trigger; do
  objects+=("drivers/trigger/CMakeFiles/plenopiv_trigger.dir/gpiod/$source.cpp.o")
done
grep -q "gpiod/gpio_chip_v2.cpp.o" "$dir/build.ninja" || { echo "CMake did not pick gpio_chip_v2.cpp"; exit 1; }
ninja -C "$dir" "${objects[@]}"

# The chip layer linked with libgpiod 2 and run: a missing chip is reported as such.
cat > "$dir/gpio_chip_v2_smoke.cpp" <<'CPP'
#include <cerrno>
#include <cstdio>
#include <cstring>
#include "drivers/trigger/gpiod/gpio_chip.hpp"
int main() {
  const std::string version = plenopiv::drivers::GpioChip::library_version();
  errno = 0;
  const bool opened = plenopiv::drivers::GpioChip::open("gpiochip97") != nullptr;
  std::printf("libgpiod %s: gpiochip97 %s (%s)\n", version.c_str(), opened ? "opened" : "not opened",
              std::strerror(errno));
  return version.rfind("2.", 0) == 0 && !opened && errno == ENOENT ? 0 : 1;
}
CPP
c++ -std=c++20 -I. -I"$deps/root/usr/include" "$dir/gpio_chip_v2_smoke.cpp" \
  "$dir/drivers/trigger/CMakeFiles/plenopiv_trigger.dir/gpiod/gpio_chip_v2.cpp.o" \
  -L"$libdir" -lgpiod -Wl,-rpath,"$libdir" -o "$dir/gpio_chip_v2_smoke"
"$dir/gpio_chip_v2_smoke"
