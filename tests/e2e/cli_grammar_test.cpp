// One grammar for every `plenopiv` command, run as a real child process: --camera FILE, -o/--output,
// -c/--config and --threads where they apply; old spellings refused with a CLI11 error and a hint.
#include <gtest/gtest.h>

#include <filesystem>
#include <string>
#include <vector>

#include "tests/support/child_process.hpp"
#include "tests/support/temp_dir.hpp"

namespace plenopiv {
namespace {

namespace fs = std::filesystem;
using testing_support::binary;
using testing_support::run_command;

const std::string kCamera = std::string(PLENOPIV_SOURCE_DIR) + "/systemd/config/camera-small.yaml";
const std::string kProcessConfig = std::string(PLENOPIV_SOURCE_DIR) + "/systemd/config/process.yaml";

int plenopiv(std::vector<std::string> args, std::string& out) {
  args.insert(args.begin(), binary("plenopiv"));
  return run_command(args, out);
}

// CLI11's exit codes: a required option missing, an argument no command takes.
constexpr int kRequiredError = 106, kExtrasError = 109;

TEST(CliGrammar, TheCameraFileIsTheCameraOptionInEveryCommand) {
  std::string out;
  ASSERT_EQ(plenopiv({"camera", "--camera", kCamera}, out), 0) << out;
  EXPECT_NE(out.find("microlenses"), std::string::npos) << out;

  // The positional form is gone: a CLI11 error, and a hint naming the spelling that replaced it.
  EXPECT_EQ(plenopiv({"camera", kCamera}, out), kRequiredError) << out;
  EXPECT_NE(out.find("--camera is required"), std::string::npos) << out;
  EXPECT_NE(out.find("a camera file is given as --camera FILE"), std::string::npos) << out;
  EXPECT_EQ(plenopiv({"reconstruct", kCamera, "raw.tif", "--extent", "0", "1", "0", "1", "0", "1", "-o", "v.h5"}, out),
            kRequiredError)
      << out;
  EXPECT_NE(out.find("--camera FILE"), std::string::npos) << out;
  EXPECT_EQ(plenopiv({"process", kCamera, "a.tif", "b.tif", "-c", kProcessConfig, "-o", "v.h5"}, out), kExtrasError)
      << out;
  EXPECT_NE(out.find("--camera FILE"), std::string::npos) << out;
}

TEST(CliGrammar, OutputIsDashOOrDashDashOutputAndOutIsRefused) {
  std::string out;
  EXPECT_EQ(plenopiv({"reconstruct", "--camera", kCamera, "raw.tif", "--extent", "0", "1", "0", "1", "0", "1", "--out",
                      "v.h5"},
                     out),
            kRequiredError)
      << out;
  EXPECT_NE(out.find("--output is required"), std::string::npos) << out;
  EXPECT_NE(out.find("--out is spelled -o/--output"), std::string::npos) << out;
  // The new spelling parses: the missing image is then bad input (2), named.
  const fs::path missing = testing_support::temp_dir("cli-grammar") / "missing.tif";
  EXPECT_EQ(plenopiv({"reconstruct", "--camera", kCamera, missing.string(), "--extent", "0", "1", "0", "1", "0", "1",
                      "--output", (testing_support::temp_dir("cli-grammar") / "v.h5").string()},
                     out),
            2)
      << out;
  EXPECT_NE(out.find("missing.tif"), std::string::npos) << out;
}

// Every command that computes takes --threads (0: all cores); a negative count is bad input, named.
TEST(CliGrammar, EveryComputeCommandTakesThreads) {
  const std::vector<std::vector<std::string>> commands{
      {"reconstruct", "--camera", kCamera, "raw.tif", "--extent", "0", "1", "0", "1", "0", "1", "-o", "v.h5"},
      {"correlate", "a.h5", "b.h5", "--dt", "0.001", "-o", "v.h5"},
      {"process", "--camera", kCamera, "a.tif", "b.tif", "-c", kProcessConfig, "--nominal", "-o", "v.h5"},
      {"refocus", "--camera", kCamera, "--calibration", "cal.h5", "raw.tif", "-o", "stack.tif"},
      {"perspective", "--camera", kCamera, "--calibration", "cal.h5", "raw.tif", "--u", "0", "--v", "0", "-o", "v.tif"},
      {"calibrate", "--camera", kCamera, "--white", "white.tif", "-o", "cal.h5"},
      {"simulate", "white", "--camera", kCamera, "-o", "white.tif"},
      {"simulate", "calibration", "--camera", kCamera, "-o", "cal.tif"},
      {"simulate", "particles", "--camera", kCamera, "--particles", "p.csv", "-o", "p.tif"},
      {"simulate", "pair", "--camera", kCamera, "--ppm", "1", "--uniform", "0,0,0", "-o", "pair"}};
  for (std::vector<std::string> args : commands) {
    args.insert(args.end(), {"--threads", "-1"});
    std::string out;
    EXPECT_EQ(plenopiv(args, out), 2) << args[0] << ": " << out;
    EXPECT_NE(out.find("--threads: must be >= 0"), std::string::npos) << args[0] << ": " << out;
  }
}

TEST(CliGrammar, ConfigIsDashCOrDashDashConfig) {
  std::string out;
  const std::string missing = (testing_support::temp_dir("cli-grammar") / "no-such.yaml").string();
  for (const std::vector<std::string>& args :
       {std::vector<std::string>{"correlate", "a.h5", "b.h5", "-c", missing, "-o", "v.h5"},
        std::vector<std::string>{"process", "--camera", kCamera, "a.tif", "b.tif", "-c", missing, "--nominal", "-o",
                                 "v.h5"}}) {
    EXPECT_EQ(plenopiv(args, out), 2) << args[0] << ": " << out;
    EXPECT_NE(out.find("no-such.yaml"), std::string::npos) << args[0] << ": " << out;
  }
}

// The control options may follow the command, nested ones too: a missing daemon is then exit 3
// (no answer), not a command-line error.
TEST(CliGrammar, ControlOptionsAfterANestedCommand) {
  const std::string endpoint = "tcp://127.0.0.1:" + std::to_string(testing_support::free_tcp_port());
  std::string out;
  EXPECT_EQ(plenopiv({"run", "stop", "--endpoint", endpoint, "--timeout", "0.3"}, out), 3) << out;
  EXPECT_NE(out.find("no reply from plenopivd at " + endpoint), std::string::npos) << out;
}

TEST(CliGrammar, HelpListsTheExitCodes) {
  std::string out;
  ASSERT_EQ(plenopiv({"--help"}, out), 0) << out;
  for (const char* line :
       {"Exit codes:", "  2        bad input", "  3        no answer", "  4        plenopivd refused"})
    EXPECT_NE(out.find(line), std::string::npos) << line << "\n" << out;
}

}  // namespace
}  // namespace plenopiv
