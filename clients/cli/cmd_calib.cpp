// `plenopiv calibrate`: white (and optionally calibration and dark) frames + camera file ->
// calibration file (HDF5).
#include <chrono>
#include <iostream>
#include <memory>

#include "clients/cli/calibration_frames.hpp"
#include "clients/cli/commands.hpp"
#include "clients/cli/options.hpp"
#include "core/calib/calibration.hpp"
#include "core/calib/calibration_file.hpp"
#include "core/optics/camera_file.hpp"

namespace plenopiv::client {
namespace {

struct CalibrateArgs {
  std::string camera;
  std::vector<std::string> calibration_images;
  std::vector<std::string> white_images;
  std::vector<std::string> dark_images;
  std::string output;
  int threads = 0;
};

void run_calibrate(const CalibrateArgs& args) {
  const auto limit = thread_limit(args.threads);
  const auto start = std::chrono::steady_clock::now();
  const optics::CameraModel camera = optics::load_camera_file(args.camera);
  double white_outside = 0;
  const calib::Calibration cal =
      calibrate_from_files(camera, {args.white_images, args.calibration_images, args.dark_images}, &white_outside);
  calib::write_calibration_h5(args.output, cal);
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  std::cout << args.output << "\n"
            << calib::describe(cal) << "  white outside      " << 100 * white_outside
            << " % of the white's light lies outside the " << cal.microlens_image_diameter_px
            << " px microlens image disks (set to 0; a large share means the\n"
            << "                     camera file's f-number or s_i does not match the lens images)\n"
            << "  time               " << seconds << " s\n";
}

}  // namespace

void add_calib_commands(CLI::App& app) {
  auto args = std::make_shared<CalibrateArgs>();  // owned by the callback, which the app keeps
  auto* cmd = app.add_subcommand(
      "calibrate",
      "find the microlens centres and the white correction; write a calibration file (HDF5). Centres come "
      "from the calibration image when given, else from the white image alone (docs/calibration.md)");
  add_camera_option(cmd, args->camera)->required();
  cmd->add_option("--calibration-image", args->calibration_images,
                  "optional: frame(s) taken with the aperture stopped down, white target (one spot per microlens; "
                  "averaged); the preferred source of the centres when given")
      ->expected(1, -1);
  cmd->add_option("--white", args->white_images,
                  "frame(s) taken with the aperture as used, white target (averaged): the white correction, and "
                  "the centres when no calibration image is given")
      ->required()
      ->expected(1, -1);
  cmd->add_option("--dark", args->dark_images,
                  "optional: frame(s) with the lens capped at the same exposure (averaged, subtracted from the "
                  "white and calibration images)")
      ->expected(1, -1);
  cmd->add_option("-o,--output", args->output, "calibration file to write (.h5)")->required();
  add_threads_option(cmd, args->threads);
  cmd->footer("Frames: PNG (8/16-bit) or TIFF (8/16-bit, or float with finite values).");
  cmd->callback([args] { run_calibrate(*args); });
}

}  // namespace plenopiv::client
