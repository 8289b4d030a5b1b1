// The alignment preview: frame A of a recorded pair downsampled and refocused at one depth, for
// topic `preview` while a run acquires.
#pragma once

#include "core/base/image.hpp"
#include "core/calib/calibration_file.hpp"
#include "core/optics/camera_model.hpp"
#include "daemon/run_config.hpp"
#include "drivers/camera/camera.hpp"
#include "plenopiv.pb.h"

namespace plenopiv::daemon {

struct Preview {
  msg::PreviewHeader header;  // everything but run_id
  ImageF raw;                 // frame A, the mean of each downsample x downsample block (counts)
  ImageF refocused;           // frame A refocused at z_mm: one pixel per microlens
};

// Made once per run from the camera, its calibration (lens centres and white correction) and the
// run's preview settings; then make() per preview, from any thread (it keeps no state).
class PreviewMaker {
 public:
  PreviewMaker(optics::CameraModel camera, calib::LoadedCalibration calibration, PreviewSettings settings);
  // InputError when the frame is not the sensor's size (lightfield::rectify's message).
  Preview make(const drivers::FramePair& pair) const;

 private:
  optics::CameraModel camera_;
  calib::LoadedCalibration calibration_;
  PreviewSettings settings_;
  double alpha_;  // lightfield::alpha_for_depth of z_mm
};

}  // namespace plenopiv::daemon
