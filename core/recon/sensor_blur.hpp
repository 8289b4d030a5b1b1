// The sensor blur B of MartSettings::sensor_blur_sigma_mm on a whole sensor image (OpenCV's
// separable Gaussian). Internal to core/recon.
#pragma once

#include <opencv2/core.hpp>

#include <span>

#include "core/recon/weights.hpp"

namespace plenopiv::recon::detail {

// Applied in place; light blurred off the sensor is lost, as on the camera. Each output pixel is
// the same sum whatever the threads.
class SensorBlur {
 public:
  SensorBlur(const WeightingOperator& op, double sigma_mm);
  bool active() const { return sigma_px_ > 0; }
  void apply(std::span<float> image);

 private:
  int width_, height_;
  double sigma_px_;
  cv::Mat scratch_;
};

}  // namespace plenopiv::recon::detail
