// Calibration spots: hot-pixel removal, thresholding, connected components, weighted centroids.
#include "core/calib/spots.hpp"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <opencv2/imgproc.hpp>
#include <string>

#include "core/base/errors.hpp"

namespace plenopiv::calib {
namespace {

// Levels of a strided sample of the image: ~1 M values are plenty for levels that hold over the
// whole frame, and keep this step cheap on paper-size images.
struct Levels {
  double median = 0;
  double mad = 0;
  double bright = 0;
};

Levels image_levels(const ImageF& image) {
  const std::size_t n = image.size();
  // An odd stride so that the sample does not march down one column of the lattice.
  const std::size_t step = std::max<std::size_t>(1, n / 1000000) | 1;
  std::vector<float> sample;
  sample.reserve(n / step + 1);
  for (std::size_t k = 0; k < n; k += step) sample.push_back(image.pixels[k]);
  auto at = [&](double q) {
    const std::size_t k = std::min(sample.size() - 1, std::size_t(q * double(sample.size() - 1)));
    std::nth_element(sample.begin(), sample.begin() + k, sample.end());
    return double(sample[k]);
  };
  Levels l;
  l.bright = at(0.999);
  l.median = at(0.5);
  for (float& v : sample) v = std::abs(v - float(l.median));
  l.mad = at(0.5);
  return l;
}

}  // namespace

std::vector<Spot> find_spots(const ImageF& image, const SpotOptions& options, SpotImageStats* stats) {
  const int w = image.width, h = image.height;
  if (w < 3 || h < 3 || image.size() != std::size_t(w) * h) {
    throw InputError("calibration image: empty or malformed (" + std::to_string(w) + " x " + std::to_string(h) +
                     " pixels)");
  }
  for (std::size_t k = 0; k < image.size(); ++k) {
    const float v = image.pixels[k];
    if (!std::isfinite(v) || v < 0) {
      throw InputError("calibration image: pixel (" + std::to_string(k % w) + ", " + std::to_string(k / w) + ") is " +
                       std::to_string(v) + "; values must be finite and non-negative");
    }
  }
  const Levels levels = image_levels(image);
  SpotImageStats st;
  st.background = levels.median;
  st.noise_sigma = 1.4826 * levels.mad;
  st.threshold = levels.median + std::max(options.threshold_sigma * st.noise_sigma,
                                          options.threshold_fraction * (levels.bright - levels.median));
  if (!(st.threshold > levels.median)) st.threshold = levels.median + 0.5;  // a flat image

  // Hot pixels: far above the noise and `hot_pixel_ratio` times brighter than every neighbour
  // (a spot's centre never is: its neighbours share its light). They are few: kept as a sorted
  // list of (index, neighbours' median) rather than a cleaned copy of a paper-size image.
  const float bg = float(st.background);
  const float floor_excess = float(std::max(st.threshold - st.background, 1e-6));
  std::vector<std::vector<std::pair<std::size_t, float>>> hot_rows(h);
  cv::Mat mask(h, w, CV_8U);
  const float thr = float(st.threshold);
  tbb::parallel_for(0, h, [&](int y) {
    auto* m = mask.ptr<std::uint8_t>(y);
    for (int x = 0; x < w; ++x) {
      const float value = image.at(x, y);
      m[x] = value > thr ? 255 : 0;
      if (y == 0 || y == h - 1 || x == 0 || x == w - 1 || value - bg < floor_excess) continue;
      float nb[8];
      int k = 0;
      float top = 0;
      for (int dy = -1; dy <= 1; ++dy) {
        for (int dx = -1; dx <= 1; ++dx) {
          if (dx == 0 && dy == 0) continue;
          nb[k] = image.at(x + dx, y + dy);
          top = std::max(top, nb[k] - bg);
          ++k;
        }
      }
      if (value - bg > float(options.hot_pixel_ratio) * std::max(top, float(st.noise_sigma))) {
        std::nth_element(nb, nb + 4, nb + 8);
        hot_rows[y].push_back({std::size_t(y) * w + x, nb[4]});
        m[x] = nb[4] > thr ? 255 : 0;
      }
    }
  });
  std::vector<std::pair<std::size_t, float>> hot;
  for (const auto& r : hot_rows) hot.insert(hot.end(), r.begin(), r.end());
  st.hot_pixels = int(hot.size());
  auto cleaned = [&](int x, int y) {
    const float v = image.at(x, y);
    if (hot.empty()) return v;
    const std::size_t k = std::size_t(y) * w + x;
    const auto it = std::lower_bound(hot.begin(), hot.end(), std::pair<std::size_t, float>{k, -1e30f});
    return it != hot.end() && it->first == k ? it->second : v;
  };

  cv::Mat labels, boxes, centroids;
  const int n = cv::connectedComponentsWithStats(mask, labels, boxes, centroids, 8, CV_32S);

  std::vector<Spot> spots(std::max(n - 1, 0));
  std::vector<std::uint8_t> keep(spots.size(), 0);
  std::vector<std::uint8_t> too_large(spots.size(), 0), at_border(spots.size(), 0);
  tbb::parallel_for(1, n, [&](int label) {
    const int* b = boxes.ptr<int>(label);
    const int x0 = b[cv::CC_STAT_LEFT], y0 = b[cv::CC_STAT_TOP];
    const int x1 = x0 + b[cv::CC_STAT_WIDTH] - 1, y1 = y0 + b[cv::CC_STAT_HEIGHT] - 1;
    const int area = b[cv::CC_STAT_AREA];
    if (options.max_area_px > 0 && area > options.max_area_px) {
      too_large[label - 1] = 1;
      return;
    }
    if (x0 == 0 || y0 == 0 || x1 == w - 1 || y1 == h - 1) {
      at_border[label - 1] = 1;
      return;
    }
    double sw = 0, sx = 0, sy = 0;
    for (int y = y0 - 1; y <= y1 + 1; ++y) {
      const int* lab = labels.ptr<int>(y);
      for (int x = x0 - 1; x <= x1 + 1; ++x) {
        if (lab[x] != 0 && lab[x] != label) continue;
        const double v = std::max(0.0f, cleaned(x, y) - bg);
        sw += v;
        sx += v * x;
        sy += v * y;
      }
    }
    if (sw <= 0) return;
    spots[label - 1] = Spot{sx / sw, sy / sw, sw, area};
    keep[label - 1] = 1;
  });
  std::vector<Spot> out;
  out.reserve(spots.size());
  for (std::size_t k = 0; k < spots.size(); ++k) {
    if (keep[k]) out.push_back(spots[k]);
    st.rejected_large += too_large[k];
    st.rejected_border += at_border[k];
  }
  if (stats) *stats = st;
  return out;
}

}  // namespace plenopiv::calib
