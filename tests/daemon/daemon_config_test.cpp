// plenopivd.yaml: defaults, relative paths, and refused endpoints and keys.
#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>

#include "core/base/errors.hpp"
#include "daemon/daemon_config.hpp"

namespace plenopiv::daemon {
namespace {

std::filesystem::path write_temp(const std::string& name, const std::string& text) {
  // One directory per process: ctest -j runs the tests of this file in parallel processes.
  const auto dir = std::filesystem::temp_directory_path() /
                   ("plenopiv-test-config-" + std::to_string(::getpid()));
  std::filesystem::create_directories(dir);
  const auto path = dir / name;
  std::ofstream(path) << text;
  return path;
}

std::string error_of(const std::string& text) {
  try {
    load_daemon_config(write_temp("bad.yaml", text));
  } catch (const InputError& e) {
    return e.what();
  }
  return "";
}

TEST(DaemonConfig, ShippedDefaultLoads) {
  const DaemonConfig c =
      load_daemon_config(std::string(PLENOPIV_SOURCE_DIR) + "/systemd/config/plenopivd.yaml");
  EXPECT_EQ(c.control_endpoint, "tcp://127.0.0.1:5555");
  EXPECT_EQ(c.publish_endpoint, "tcp://*:5556");
  EXPECT_TRUE(std::filesystem::exists(c.camera_file)) << c.camera_file;
}

TEST(DaemonConfig, RelativePathsAreTakenFromTheConfigFolder) {
  const auto path = write_temp("rel.yaml", "data_dir: runs\ncamera_file: cams/c.yaml\n");
  const DaemonConfig c = load_daemon_config(path);
  EXPECT_EQ(c.data_dir, path.parent_path() / "runs");
  EXPECT_EQ(c.camera_file, path.parent_path() / "cams/c.yaml");
}

TEST(DaemonConfig, RemoteControlEndpointIsRefused) {
  const std::string err = error_of("control_endpoint: tcp://*:5555\n");
  EXPECT_NE(err.find("control_endpoint"), std::string::npos) << err;
  EXPECT_NE(err.find("CURVE"), std::string::npos) << err;
}

TEST(DaemonConfig, BadKeysAreNamed) {
  EXPECT_NE(error_of("contrl_endpoint: tcp://127.0.0.1:1\n").find("contrl_endpoint: unknown key"),
            std::string::npos);
  EXPECT_NE(error_of("publish_endpoint: 5556\n").find("publish_endpoint"), std::string::npos);
  EXPECT_NE(error_of("log_level: loud\n").find("log_level"), std::string::npos);
  EXPECT_NE(error_of("publish_high_water_mark: 0\n").find("publish_high_water_mark"),
            std::string::npos);
}

}  // namespace
}  // namespace plenopiv::daemon
