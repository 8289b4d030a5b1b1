// `plenopiv refocus` (focal stack TIFF + PNG contact sheet) and `plenopiv perspective` (views).
#include <iostream>
#include <memory>
#include <sstream>

#include "clients/cli/commands.hpp"
#include "clients/cli/depth_list.hpp"
#include "clients/cli/options.hpp"
#include "clients/cli/progress.hpp"
#include "core/base/errors.hpp"
#include "core/calib/calibration_file.hpp"
#include "core/io/raw_frame.hpp"
#include "core/io/tiff.hpp"
#include "core/lightfield/light_field.hpp"
#include "core/lightfield/refocus.hpp"
#include "core/optics/camera_file.hpp"
#include "core/plot/image_sheet.hpp"

namespace plenopiv::client {
namespace {

struct LightFieldArgs {
  std::string camera;
  std::string calibration;
  std::string raw;
  bool no_white = false;
  std::string depths;  // "start:stop:step" or "a,b,c" (mm)
  std::vector<double> alphas;
  std::string output;
  std::string sheet;
  std::vector<double> u, v;
  int threads = 0;
};

lightfield::LightField load_field(const LightFieldArgs& args, optics::CameraModel& camera_out) {
  camera_out = optics::load_camera_file(args.camera);
  const calib::LoadedCalibration cal = calib::load_calibration(args.calibration, camera_out);
  camera_out = calib::camera_in_frame(camera_out, cal);
  const ImageF raw = io::read_raw_frame(args.raw);
  try {
    return lightfield::rectify(camera_out, cal.lenses, raw, args.no_white ? nullptr : &cal.white_correction);
  } catch (const InputError& e) {
    throw InputError(args.raw + ": " + e.what());
  }
}

void run_refocus(const LightFieldArgs& args) {
  const auto limit = thread_limit(args.threads);
  optics::CameraModel camera = optics::load_camera_file(args.camera);
  std::vector<double> alphas;
  std::vector<std::string> labels;
  if (!args.alphas.empty()) {
    for (double a : args.alphas) {
      if (!(a > 0)) throw InputError("--alpha: " + std::to_string(a) + " is not positive");
      alphas.push_back(a);
      std::ostringstream s;
      s << "alpha = " << a;
      labels.push_back(s.str());
    }
  } else {
    for (double z : parse_depths(args.depths.empty() ? "-10:10:1" : args.depths)) {
      alphas.push_back(lightfield::alpha_for_depth(camera, z));
      std::ostringstream s;
      s << "z = " << z << " mm";
      labels.push_back(s.str());
    }
  }
  const lightfield::LightField field = load_field(args, camera);
  Progress progress("refocus", "images", double(alphas.size()));
  std::vector<ImageF> stack;
  for (std::size_t k = 0; k < alphas.size(); ++k) {
    stack.push_back(lightfield::refocus(field, alphas[k]));
    progress.update(double(k + 1) / double(alphas.size()));
  }
  // Each page says what it is: the depth it brings into focus and its alpha (eqs 2-4).
  std::vector<std::string> descriptions;
  for (const double alpha : alphas) {
    std::ostringstream d;
    d.precision(9);
    d << "plenopiv refocus: z_mm=" << lightfield::depth_for_alpha(camera, alpha) << " alpha=" << alpha
      << " (depth from the nominal focal plane, object space; one pixel per microlens)";
    descriptions.push_back(d.str());
  }
  io::write_tiff_stack(args.output, stack, descriptions);
  const std::string sheet =
      args.sheet.empty() ? std::filesystem::path(args.output).replace_extension(".png").string() : args.sheet;
  plot::write_image_sheet(sheet, stack, labels, "lens");
  std::cout << args.output << ": " << stack.size() << " refocused images of " << stack[0].width << " x "
            << stack[0].height << " (one pixel per microlens)\n"
            << sheet << ": contact sheet\n";
}

void run_perspective(const LightFieldArgs& args) {
  if (args.u.size() != args.v.size()) {
    throw InputError("--u and --v: give as many u as v values (" + std::to_string(args.u.size()) + " vs " +
                     std::to_string(args.v.size()) + ")");
  }
  const auto limit = thread_limit(args.threads);
  optics::CameraModel camera = optics::load_camera_file(args.camera);
  const lightfield::LightField field = load_field(args, camera);
  std::vector<ImageF> views;
  std::vector<std::string> labels;
  for (std::size_t k = 0; k < args.u.size(); ++k) {
    views.push_back(lightfield::perspective_view(field, args.u[k], args.v[k]));
    std::ostringstream s;
    s << "u = " << args.u[k] << " mm, v = " << args.v[k] << " mm";
    labels.push_back(s.str());
  }
  std::vector<std::string> descriptions;
  for (std::size_t k = 0; k < args.u.size(); ++k) {
    std::ostringstream d;
    d.precision(9);
    d << "plenopiv perspective: u_mm=" << args.u[k] << " v_mm=" << args.v[k]
      << " (position on the main lens's aperture; one pixel per microlens)";
    descriptions.push_back(d.str());
  }
  io::write_tiff_stack(args.output, views, descriptions);
  if (!args.sheet.empty()) plot::write_image_sheet(args.sheet, views, labels, "lens");
  std::cout << args.output << ": " << views.size() << " perspective views of " << views[0].width << " x "
            << views[0].height << "\n";
}

void add_common(CLI::App* cmd, LightFieldArgs& args) {
  add_camera_option(cmd, args.camera)->required();
  cmd->add_option("--calibration", args.calibration, "calibration file from `plenopiv calibrate`")->required();
  cmd->add_option("raw", args.raw, "raw plenoptic image (PNG, or TIFF of 8/16-bit or float)")->required();
  cmd->add_flag("--no-white", args.no_white, "do not divide by the white correction");
  cmd->add_option("-o,--output", args.output, "multi-page float32 TIFF to write")->required();
  add_threads_option(cmd, args.threads);
}

}  // namespace

void add_lightfield_commands(CLI::App& app) {
  auto refocus_args = std::make_shared<LightFieldArgs>();
  auto* refocus =
      app.add_subcommand("refocus", "computational refocusing (eqs 2-4): a focal stack and a contact sheet");
  add_common(refocus, *refocus_args);
  refocus->add_option("--z", refocus_args->depths, "object depths in mm: start:stop:step or a,b,c (default -10:10:1)");
  refocus->add_option("--alpha", refocus_args->alphas, "refocus at these alpha = s'_i/s_i instead of depths");
  refocus->add_option("--sheet", refocus_args->sheet, "PNG contact sheet (default: the output with .png)");
  refocus->callback([refocus_args] { run_refocus(*refocus_args); });

  auto view_args = std::make_shared<LightFieldArgs>();
  auto* view = app.add_subcommand("perspective", "perspective views from aperture points (u, v) mm (sec 3.4)");
  add_common(view, *view_args);
  view->add_option("--u", view_args->u, "aperture u of each view, mm")->required();
  view->add_option("--v", view_args->v, "aperture v of each view, mm")->required();
  view->add_option("--sheet", view_args->sheet, "also write a PNG contact sheet here");
  view->callback([view_args] { run_perspective(*view_args); });
}

}  // namespace plenopiv::client
