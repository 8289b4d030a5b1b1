// systemd/plenopivd.service passes `systemd-analyze verify` (with ExecStart pointed at this build).
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
  std::ifstream in(std::string(PLENOPIV_SOURCE_DIR) + "/systemd/plenopivd.service");
  std::stringstream text;
  text << in.rdbuf();
  std::string unit = text.str();
  for (const char* required :
       {"Type=notify", "WatchdogSec=", "DevicePolicy=closed", "DeviceAllow=char-gpiochip",
        "DeviceAllow=char-usb_device", "ProtectSystem=strict", "ReadWritePaths=/var/lib/plenopiv",
        "NoNewPrivileges=yes", "--config /etc/plenopiv/plenopivd.yaml"}) {
    EXPECT_NE(unit.find(required), std::string::npos) << "the unit lacks " << required;
  }
  // verify checks that ExecStart exists: point it at the binary this build made.
  const std::string installed = "/usr/bin/plenopivd";
  unit.replace(unit.find(installed), installed.size(), testing_support::binary("plenopivd"));
  const auto dir = testing_support::temp_dir("systemd");
  const auto path = dir / "plenopivd.service";
  std::ofstream(path) << unit;
  std::string out;
  const int rc = testing_support::run_command({analyze, "verify", path.string()}, out);
  EXPECT_EQ(rc, 0) << out;
  EXPECT_EQ(out, "") << "systemd-analyze verify warned";
}

}  // namespace
}  // namespace plenopiv
