// The unit the build configures from systemd/plenopivd.service.in passes `systemd-analyze verify` (with
// ExecStart pointed at this build); scripts/test-package.sh verifies the installed one.
#include <gtest/gtest.h>

#include <fstream>
#include <sstream>

#include "tests/support/child_process.hpp"
#include "tests/support/temp_dir.hpp"

namespace plenopiv {
namespace {

TEST(SystemdUnit, PassesSystemdAnalyzeVerify) {
  const std::string analyze = "/usr/bin/systemd-analyze";
  if (!std::filesystem::exists(analyze)) {
    GTEST_SKIP() << "systemd-analyze is not installed (Debian package systemd; scripts/setup.sh)";
  }
  std::ifstream in(std::string(PLENOPIV_BINARY_DIR) + "/systemd/plenopivd.service");
  ASSERT_TRUE(in) << "the build did not configure systemd/plenopivd.service (packaging/CMakeLists.txt)";
  std::stringstream text;
  text << in.rdbuf();
  std::string unit = text.str();
  for (const char* required :
       {"Type=notify", "WatchdogSec=", "DevicePolicy=closed", "DeviceAllow=char-gpiochip",
        "DeviceAllow=char-usb_device", "ProtectSystem=strict", "ReadWritePaths=/var/lib/plenopiv",
        "NoNewPrivileges=yes", "/plenopiv/plenopivd.yaml\n", "User=plenopiv"}) {
    EXPECT_NE(unit.find(required), std::string::npos) << "the unit lacks " << required;
  }
  EXPECT_EQ(unit.find("@CMAKE_"), std::string::npos) << "a path was left unconfigured:\n" << unit;
  // verify checks that ExecStart exists: point it at the binary this build made.
  const std::string exec_start = "ExecStart=";
  const auto program = unit.find(exec_start) + exec_start.size();
  const auto program_end = unit.find(' ', program);
  ASSERT_NE(program_end, std::string::npos) << unit;
  EXPECT_TRUE(unit.substr(program, program_end - program).ends_with("/bin/plenopivd")) << unit;
  unit.replace(program, program_end - program, testing_support::binary("plenopivd"));
  const auto dir = testing_support::temp_dir("systemd");
  const auto path = dir / "plenopivd.service";
  std::ofstream(path) << unit;
  std::string out;
  // Its man page plenopivd(8) exists once installed (scripts/test-package.sh verifies that unit in full).
  const int rc = testing_support::run_command({analyze, "verify", "--man=no", path.string()}, out);
  EXPECT_EQ(rc, 0) << out;
  EXPECT_EQ(out, "") << "systemd-analyze verify warned";
}

}  // namespace
}  // namespace plenopiv
