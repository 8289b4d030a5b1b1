// The sensor blur of MART's forward model, a Gaussian on the whole sensor image (OpenCV).
#include "core/recon/sensor_blur.hpp"

#include <opencv2/imgproc.hpp>

namespace plenopiv::recon::detail {

SensorBlur::SensorBlur(const WeightingOperator& op, double sigma_mm)
    : width_(op.image_width()), height_(op.image_height()), sigma_px_(sigma_mm / op.geometry().pixel_pitch) {}

void SensorBlur::apply(std::span<float> image) {
  cv::Mat in(height_, width_, CV_32F, image.data());
  cv::GaussianBlur(in, scratch_, cv::Size(0, 0), sigma_px_, sigma_px_, cv::BORDER_CONSTANT);
  scratch_.copyTo(in);
}

}  // namespace plenopiv::recon::detail
