// Single-channel TIFF images: 8- or 16-bit in, 16-bit (or float32 stacks) out.
#pragma once

#include <filesystem>
#include <functional>
#include <span>
#include <string>
#include <vector>

#include "core/base/image.hpp"

namespace plenopiv::io {

// Reads the first page of an 8- or 16-bit single-channel TIFF (8-bit values are kept as they
// are, 0-255). Anything else (colour, float, corrupt, missing) is an InputError naming the file.
ImageU16 read_tiff_u16(const std::filesystem::path& path);
// The same into `image`, whose buffer is reused when it already has the file's size (a camera's
// frame buffers); on an error `image` is left as it was or holds part of the file.
void read_tiff_u16(const std::filesystem::path& path, ImageU16& image);
// Reads the first page of a single-channel TIFF as float: 8- or 16-bit unsigned (values as they
// are), or 32/64-bit float whose every value is finite. Anything else is an InputError naming the
// file (and, for a non-finite value, the pixel). Raw frames go through io::read_raw_frame.
ImageF read_tiff_float(const std::filesystem::path& path);

// A TIFF's first page as its header describes it, checked against the file: width, height, bits.
struct TiffInfo {
  int width = 0, height = 0, bits = 0;
};
// Reads the header only and checks that every strip or tile the page names lies inside the file:
// a truncated or damaged frame is found without reading its pixels. InputError naming the file.
TiffInfo check_tiff(const std::filesystem::path& path);

// Writes a 16-bit single-channel TIFF, atomically, past the page cache where the file system takes
// O_DIRECT (io::DirectWriter): a recorder's frames cost a copy, not page-cache churn.
// `sync_folder`: as io::write_atomically (false: the caller flushes the folder once for several files).
// `visit_rows`, if set, sees each strip's pixels (whole rows, in order, each once) just before they
// are copied out, while they are in cache: a frame's statistics for the price of no extra read.
using RowsVisitor = std::function<void(std::span<const std::uint16_t>)>;
void write_tiff(const std::filesystem::path& path, const ImageU16& image, bool sync_folder = true,
                const RowsVisitor& visit_rows = {});
// Writes float32 pages (a focal stack, say) as one multi-page TIFF, atomically. `descriptions`
// (empty, or one per page): each page's ImageDescription, what the page is (e.g. its depth).
void write_tiff_stack(const std::filesystem::path& path, const std::vector<ImageF>& pages,
                      const std::vector<std::string>& descriptions = {});
// Reads every page of a float32 or 16-bit stack as float.
std::vector<ImageF> read_tiff_stack(const std::filesystem::path& path);
// Each page's ImageDescription ("" where a page has none).
std::vector<std::string> read_tiff_descriptions(const std::filesystem::path& path);

}  // namespace plenopiv::io
