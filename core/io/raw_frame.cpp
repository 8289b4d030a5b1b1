// Raw frames from disk: PNG through OpenCV, TIFF through libtiff, both to float counts.
#include "core/io/raw_frame.hpp"

#include <algorithm>
#include <fstream>
#include <opencv2/imgcodecs.hpp>
#include <stdexcept>
#include <string>

#include "core/base/errors.hpp"
#include "core/io/tiff.hpp"

namespace plenopiv::io {
namespace {

enum class Format { png, tiff, unknown };

Format sniff(const std::filesystem::path& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) {
    throw InputError(path.string() + (std::filesystem::exists(path) ? ": cannot read" : ": no such file"));
  }
  unsigned char head[8] = {};
  in.read(reinterpret_cast<char*>(head), sizeof head);
  const std::streamsize n = in.gcount();
  static const unsigned char png[8] = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n'};
  if (n == 8 && std::equal(head, head + 8, png)) return Format::png;
  if (n >= 4 && ((head[0] == 'I' && head[1] == 'I' && (head[2] == 42 || head[2] == 43) && head[3] == 0) ||
                 (head[0] == 'M' && head[1] == 'M' && head[2] == 0 && (head[3] == 42 || head[3] == 43)))) {
    return Format::tiff;
  }
  return Format::unknown;
}

ImageF read_png(const std::filesystem::path& path) {
  const cv::Mat m = cv::imread(path.string(), cv::IMREAD_UNCHANGED);
  if (m.empty()) throw InputError(path.string() + ": corrupt or unreadable PNG");
  if (m.depth() != CV_8U && m.depth() != CV_16U) {
    throw InputError(path.string() + ": expected 8- or 16-bit PNG samples");
  }
  const int channels = m.channels();
  if (channels != 1 && channels != 3 && channels != 4) {
    throw InputError(path.string() + ": PNG with " + std::to_string(channels) + " channels; expected grey");
  }
  ImageF out(m.cols, m.rows);
  for (int y = 0; y < m.rows; ++y) {
    for (int x = 0; x < m.cols; ++x) {
      auto sample = [&](int c) {
        return m.depth() == CV_8U ? float(m.ptr<std::uint8_t>(y)[x * channels + c])
                                  : float(m.ptr<std::uint16_t>(y)[x * channels + c]);
      };
      const float v = sample(0);
      // A grey frame stored as colour has equal channels; a real colour image is not a raw frame.
      if (channels >= 3 && (sample(1) != v || sample(2) != v)) {
        throw InputError(path.string() + ": a colour PNG (pixel (" + std::to_string(x) + ", " + std::to_string(y) +
                         ") is not grey); a raw plenoptic frame has one channel");
      }
      out.at(x, y) = v;
    }
  }
  return out;
}

}  // namespace

ImageF read_raw_frame(const std::filesystem::path& path) {
  switch (sniff(path)) {
    case Format::png:
      return read_png(path);
    case Format::tiff:
      return read_tiff_float(path);
    case Format::unknown:
      break;
  }
  throw InputError(path.string() +
                   ": not a PNG or TIFF file (raw frames are read as PNG, or TIFF of 8/16-bit "
                   "unsigned or float samples)");
}

ImageF read_mean_frame(const std::vector<std::string>& paths, const std::string& what) {
  if (paths.empty()) throw std::logic_error("read_mean_frame: no files");
  ImageF mean;
  std::vector<double> sum;
  for (const std::string& path : paths) {
    const ImageF frame = read_raw_frame(path);
    if (sum.empty()) {
      mean = ImageF(frame.width, frame.height);
      sum.assign(frame.size(), 0.0);
    } else if (frame.width != mean.width || frame.height != mean.height) {
      throw InputError(path + ": " + what + " frame is " + std::to_string(frame.width) + " x " +
                       std::to_string(frame.height) + " pixels, " + paths.front() + " is " +
                       std::to_string(mean.width) + " x " + std::to_string(mean.height));
    }
    for (std::size_t k = 0; k < frame.size(); ++k) sum[k] += frame.pixels[k];
  }
  for (std::size_t k = 0; k < sum.size(); ++k) mean.pixels[k] = float(sum[k] / double(paths.size()));
  return mean;
}

}  // namespace plenopiv::io
