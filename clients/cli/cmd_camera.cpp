// `plenopiv camera`: load a camera file, validate it and print its derived geometry.
#include <iostream>
#include <memory>

#include "clients/cli/commands.hpp"
#include "clients/cli/options.hpp"
#include "core/optics/camera_file.hpp"

namespace plenopiv::client {

void add_camera_commands(CLI::App& app) {
  auto* camera = app.add_subcommand("camera", "validate a camera file and show its geometry");
  auto file = std::make_shared<std::string>();  // owned by the callback, which the app keeps
  add_camera_option(camera, *file)->required();
  camera->callback([file] {
    const optics::CameraModel model = optics::load_camera_file(*file);
    std::cout << *file << "\n" << model.summary();
  });
}

}  // namespace plenopiv::client
