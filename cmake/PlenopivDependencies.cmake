# Finds every package of the design card (Debian packages); a missing one stops configure
# with the Debian package to install.

include(FindPkgConfig)

function(plenopiv_missing what debian_package)
  message(FATAL_ERROR
    "plenopiv: ${what} not found. Install it with: apt-get install ${debian_package}"
    " (or run: sudo scripts/setup.sh)")
endfunction()

macro(plenopiv_find_config pkg debian_package)
  find_package(${pkg} ${ARGN} CONFIG QUIET)
  if(NOT ${pkg}_FOUND)
    plenopiv_missing(${pkg} ${debian_package})
  endif()
  message(STATUS "plenopiv: found ${pkg} ${${pkg}_VERSION}")
endmacro()

macro(plenopiv_find_pkgconfig prefix module debian_package)
  pkg_check_modules(${prefix} QUIET IMPORTED_TARGET ${module})
  if(NOT ${prefix}_FOUND)
    plenopiv_missing("pkg-config module ${module}" ${debian_package})
  endif()
  message(STATUS "plenopiv: found ${module} ${${prefix}_VERSION}")
endmacro()

find_package(PkgConfig QUIET)
if(NOT PKG_CONFIG_FOUND)
  plenopiv_missing(pkg-config pkg-config)
endif()

find_package(Threads REQUIRED)

# Core numerics and file formats
plenopiv_find_config(yaml-cpp libyaml-cpp-dev)
plenopiv_find_config(TBB libtbb-dev)
plenopiv_find_config(spdlog libspdlog-dev)
plenopiv_find_config(CLI11 libcli11-dev)
plenopiv_find_config(OpenCV libopencv-dev COMPONENTS core imgproc imgcodecs)
plenopiv_find_pkgconfig(FFTW3F fftw3f libfftw3-dev)
# Vector logarithms and exponentials with the same bits on every CPU (MART's per-pixel log-ratios)
plenopiv_find_pkgconfig(SLEEF sleef libsleef-dev)
plenopiv_find_pkgconfig(LIBTIFF libtiff-4 libtiff-dev)
# Fast hashes (XXH3) of the weights cache: its key's white image and its tables' checksum
plenopiv_find_pkgconfig(XXHASH libxxhash libxxhash-dev)
find_package(HDF5 QUIET COMPONENTS C HL)
if(NOT HDF5_FOUND)
  plenopiv_missing(HDF5 libhdf5-dev)
endif()
message(STATUS "plenopiv: found HDF5 ${HDF5_VERSION}")
# CRC-32 of the files a run folder copies (libhdf5-dev depends on zlib1g-dev)
plenopiv_find_pkgconfig(ZLIB zlib zlib1g-dev)

# Preview plots (PLplot's C++ API; PNGs through its cairo driver, plplot-driver-cairo at run time)
plenopiv_find_pkgconfig(PLPLOT_CXX plplot-c++ libplplot-dev)
plenopiv_find_pkgconfig(PLPLOT plplot libplplot-dev)
# Exports: NetCDF-4 files and the zip archive of NumPy's .npz
plenopiv_find_pkgconfig(NETCDF netcdf libnetcdf-dev)
plenopiv_find_pkgconfig(LIBZIP libzip libzip-dev)

# Messaging
plenopiv_find_pkgconfig(LIBZMQ libzmq libzmq3-dev)
plenopiv_find_config(cppzmq cppzmq-dev)
find_package(Protobuf QUIET)
if(NOT Protobuf_FOUND OR NOT Protobuf_PROTOC_EXECUTABLE)
  plenopiv_missing("Protobuf (library and protoc)" "libprotobuf-dev protobuf-compiler")
endif()
message(STATUS "plenopiv: found Protobuf ${Protobuf_VERSION} (protoc ${Protobuf_PROTOC_EXECUTABLE})")

# Devices and system
if(PLENOPIV_WITH_ARAVIS)
  plenopiv_find_pkgconfig(ARAVIS aravis-0.8 libaravis-dev)
endif()
if(PLENOPIV_WITH_GPIOD)
  # v1 (1.6) or v2 (2.x): drivers/trigger builds the GpioChip of the API found.
  plenopiv_find_pkgconfig(GPIOD "libgpiod>=1.6" libgpiod-dev)
endif()
if(PLENOPIV_WITH_USB)
  plenopiv_find_pkgconfig(LIBUSB libusb-1.0 libusb-1.0-0-dev)
endif()
plenopiv_find_pkgconfig(SYSTEMD libsystemd libsystemd-dev)

# The man pages are made from the programs' --help (packaging/)
find_program(HELP2MAN help2man)
if(NOT HELP2MAN)
  plenopiv_missing(help2man help2man)
endif()

if(PLENOPIV_BUILD_TESTS)
  find_package(GTest QUIET)
  if(NOT GTest_FOUND)
    plenopiv_missing(GoogleTest "libgtest-dev libgmock-dev")
  endif()
  message(STATUS "plenopiv: found GoogleTest ${GTest_VERSION}")
endif()
