// `plenopiv calibrate`: calibration image + white images + camera file -> calibration file (HDF5).
#include <chrono>
#include <cmath>
#include <iostream>
#include <memory>
#include <numbers>

#include "clients/cli/commands.hpp"
#include "core/base/errors.hpp"
#include "core/calib/calibration.hpp"
#include "core/calib/calibration_file.hpp"
#include "core/io/tiff.hpp"
#include "core/optics/camera_file.hpp"

namespace plenopiv::client {
namespace {

struct CalibrateArgs {
  std::string camera;
  std::string calibration_image;
  std::vector<std::string> white_images;
  std::string output;
};

ImageF to_float(const ImageU16& in) {
  ImageF out(in.width, in.height);
  for (std::size_t k = 0; k < in.size(); ++k) out.pixels[k] = float(in.pixels[k]);
  return out;
}

void run_calibrate(const CalibrateArgs& args) {
  const auto start = std::chrono::steady_clock::now();
  const optics::CameraModel camera = optics::load_camera_file(args.camera);
  const ImageF image = to_float(io::read_tiff_u16(args.calibration_image));
  calib::Calibration cal;
  try {
    cal = calib::calibrate(camera, image);
  } catch (const InputError& e) {
    throw InputError(args.calibration_image + ": " + e.what());
  }
  // Fig 15 wants the average of several white images: noise in one would become a pattern.
  ImageF white;
  for (const std::string& path : args.white_images) {
    const ImageF w = to_float(io::read_tiff_u16(path));
    if (w.width != image.width || w.height != image.height) {
      throw InputError(path + ": white image is " + std::to_string(w.width) + " x " + std::to_string(w.height) +
                       " pixels, the calibration image is " + std::to_string(image.width) + " x " +
                       std::to_string(image.height));
    }
    if (white.empty()) white = ImageF(w.width, w.height, 0.0f);
    for (std::size_t k = 0; k < w.size(); ++k) white.pixels[k] += w.pixels[k] / float(args.white_images.size());
  }
  double white_outside = 0;
  cal.white_correction = calib::make_white_correction(cal, white, cal.image_stats.background, &white_outside);
  calib::write_calibration_h5(args.output, cal);

  int missing = 0, rejected = 0;
  for (auto s : cal.status) {
    missing += s == calib::LensStatus::missing;
    rejected += s == calib::LensStatus::rejected;
  }
  const double pp = cal.sensor.pixel_pitch_mm;
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  std::cout << args.output << "\n"
            << "  spots found        " << cal.spots_found << " (background " << cal.image_stats.background
            << ", noise " << cal.image_stats.noise_sigma << ", hot pixels removed " << cal.image_stats.hot_pixels << ")\n"
            << "  lenses             " << cal.status.size() << ": " << cal.lenses_measured << " measured, " << missing
            << " missing, " << rejected << " rejected (lattice position used)\n"
            << "  spot pitch         " << cal.spot_lattice.pitch_x_mm / pp << " x " << cal.spot_lattice.pitch_y_mm / pp
            << " px (" << optics::to_string(cal.spot_lattice.layout) << ")\n"
            << "  rotation           " << cal.spot_lattice.rotation_rad * 180 / std::numbers::pi << " deg\n"
            << "  offset             " << cal.spot_lattice.offset_x_mm / pp << ", " << cal.spot_lattice.offset_y_mm / pp
            << " px from the sensor centre\n"
            << "  residuals          " << cal.rms_residual_px << " px rms, " << cal.max_residual_px << " px max\n"
            << "  white outside      " << 100 * white_outside << " % of the white's light lies outside the "
            << cal.microlens_image_diameter_px << " px microlens image disks (set to 0; a large share means the\n"
            << "                     camera file's f-number or s_i does not match the lens images)\n"
            << "  time               " << seconds << " s\n";
}

}  // namespace

void add_calib_commands(CLI::App& app) {
  auto args = std::make_shared<CalibrateArgs>();  // owned by the callback, which the app keeps
  auto* cmd = app.add_subcommand("calibrate",
                                 "find the microlens centres and the white correction; write a calibration file (HDF5)");
  cmd->add_option("--camera", args->camera, "camera file (YAML)")->required();
  cmd->add_option("--calibration-image", args->calibration_image,
                  "TIFF taken with the aperture stopped down, white target (one spot per microlens)")
      ->required();
  cmd->add_option("--white", args->white_images, "TIFF(s) taken with the aperture open, white target (averaged)")
      ->required();
  cmd->add_option("-o,--output", args->output, "calibration file to write (.h5)")->required();
  cmd->callback([args] { run_calibrate(*args); });
}

}  // namespace plenopiv::client
