// Pictures (not plots: those are core/plot's) the CLI writes, i.e. `watch --preview`'s raw frame beside
// the refocused slice: encoded by OpenCV, written atomically.
#include "clients/cli/png_file.hpp"

#include <opencv2/imgcodecs.hpp>

#include <cstdint>
#include <fstream>
#include <vector>

#include "core/base/errors.hpp"
#include "core/io/atomic_file.hpp"

namespace plenopiv::client {

void write_png(const std::filesystem::path& path, const cv::Mat& image) {
  std::vector<std::uint8_t> bytes;
  if (!cv::imencode(".png", image, bytes)) throw InputError(path.string() + ": PNG encoding failed");
  io::write_atomically(path, [&](const std::filesystem::path& tmp) {
    std::ofstream out(tmp, std::ios::binary);
    out.write(reinterpret_cast<const char*>(bytes.data()), std::streamsize(bytes.size()));
    if (!out) throw InputError(path.string() + ": cannot write");
  });
}

}  // namespace plenopiv::client
