// The alignment preview: frame A of a recorded pair downsampled and refocused at one depth, for
// topic `preview` while a run acquires.
#include "daemon/preview.hpp"

#include <opencv2/imgproc.hpp>

#include <algorithm>

#include "core/lightfield/light_field.hpp"
#include "core/lightfield/refocus.hpp"
#include "core/process/pair_processor.hpp"

namespace plenopiv::daemon {

PreviewMaker::PreviewMaker(optics::CameraModel camera, calib::LoadedCalibration calibration, PreviewSettings settings)
    : camera_(calib::camera_in_frame(camera, calibration)),
      calibration_(std::move(calibration)),
      settings_(settings),
      alpha_(lightfield::alpha_for_depth(camera_, settings_.z_mm)) {}

Preview PreviewMaker::make(const drivers::FramePair& pair) const {
  const ImageF frame = process::to_float(pair.a.image);
  Preview out;
  msg::PreviewHeader& h = out.header;
  h.set_pair_index(pair.pair_index);
  h.set_host_timestamp_ns(pair.a.host_timestamp_ns);
  h.set_sensor_width_px(frame.width);
  h.set_sensor_height_px(frame.height);
  h.set_downsample(settings_.downsample);
  if (!frame.pixels.empty()) {
    const auto [lo, hi] = std::minmax_element(frame.pixels.begin(), frame.pixels.end());
    double sum = 0;
    for (const float v : frame.pixels) sum += v;
    const float full_scale = float((1u << std::clamp(pair.a.bit_depth, 1, 16)) - 1);
    const auto saturated =
        std::count_if(frame.pixels.begin(), frame.pixels.end(), [&](float v) { return v >= full_scale; });
    h.set_raw_min(*lo);
    h.set_raw_max(*hi);
    h.set_raw_mean(sum / double(frame.pixels.size()));
    h.set_saturated_fraction(double(saturated) / double(frame.pixels.size()));
  }
  // Block means (OpenCV's area interpolation), the last partial block dropped.
  const int w = std::max(1, frame.width / settings_.downsample),
            h_px = std::max(1, frame.height / settings_.downsample);
  out.raw = ImageF(w, h_px);
  const cv::Mat source(frame.height, frame.width, CV_32F, const_cast<float*>(frame.pixels.data()));
  cv::Mat target(h_px, w, CV_32F, out.raw.pixels.data());
  cv::resize(source(cv::Rect(0, 0, w * settings_.downsample, h_px * settings_.downsample)), target, target.size(), 0, 0,
             cv::INTER_AREA);
  h.set_raw_width(w);
  h.set_raw_height(h_px);

  const lightfield::LightField field =
      lightfield::rectify(camera_, calibration_.lenses, frame, &calibration_.white_correction);
  out.refocused = lightfield::refocus(field, alpha_);
  h.set_refocus_z_mm(settings_.z_mm);
  h.set_refocus_width(out.refocused.width);
  h.set_refocus_height(out.refocused.height);
  h.set_focus_measure(lightfield::focus_measure(out.refocused));
  return out;
}

}  // namespace plenopiv::daemon
