// PNG pictures the CLI writes (process previews, watch --preview): encoded by OpenCV, written atomically.
#pragma once

#include <opencv2/core.hpp>

#include <filesystem>

namespace plenopiv::client {

// `image` (8-bit grey or BGR) as a PNG at `path`, under a temporary name then renamed; InputError
// naming the file when it cannot be encoded or written.
void write_png(const std::filesystem::path& path, const cv::Mat& image);

}  // namespace plenopiv::client
