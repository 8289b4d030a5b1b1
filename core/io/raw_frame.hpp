// Raw frames from disk: the one reader every command that takes camera images uses.
#pragma once

#include <filesystem>
#include <string>
#include <vector>

#include "core/base/image.hpp"

namespace plenopiv::io {

// Reads a raw camera frame as float counts, whatever it was stored as: PNG (8- or 16-bit, grey;
// a colour PNG whose channels are all equal is read as grey) through OpenCV, or TIFF (8/16-bit
// unsigned, or 32/64-bit float with every value finite) through libtiff. The format is taken from
// the file's signature, not its name. InputError naming the file for anything else: missing,
// unreadable, corrupt, colour, signed, non-finite.
ImageF read_raw_frame(const std::filesystem::path& path);

// The mean of several frames of one size (a white or dark series): InputError naming the first
// file whose size differs from the first one's. `what` names the series in messages ("white").
ImageF read_mean_frame(const std::vector<std::string>& paths, const std::string& what);

}  // namespace plenopiv::io
