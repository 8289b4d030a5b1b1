// Fuzz target: the TIFF reader (core/io/tiff) on any file: the header check that `process --run`
// makes, a 16-bit frame, a float stack. Each reads it or refuses it naming the file.
#include <optional>

#include "core/io/tiff.hpp"
#include "tests/fuzz/fuzz_support.hpp"

using namespace plenopiv;

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const auto path = fuzzing::input_file(data, size, "frame.tif");
  std::optional<io::TiffInfo> info;
  try {
    info = io::check_tiff(path);
    fuzzing::require(info->width > 0 && info->height > 0, "check_tiff passed a TIFF without pixels");
  } catch (const InputError& e) {
    fuzzing::require_names(e, path.string());
  }
  try {
    const ImageU16 image = io::read_tiff_u16(path);
    fuzzing::require(image.width > 0 && image.height > 0 && image.size() == std::size_t(image.width) * image.height,
                     "read_tiff_u16 returned an image without pixels");
    if (info) {
      fuzzing::require(info->width == image.width && info->height == image.height,
                       "check_tiff and read_tiff_u16 disagree on the size");
    }
  } catch (const InputError& e) {
    fuzzing::require_names(e, path.string());
  }
  try {
    for (const ImageF& page : io::read_tiff_stack(path)) {
      fuzzing::require(page.size() == std::size_t(page.width) * page.height, "a stack page of the wrong size");
    }
  } catch (const InputError& e) {
    fuzzing::require_names(e, path.string());
  }
  return 0;
}
