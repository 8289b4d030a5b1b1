// Device URIs: what parses, and that every malformed one is an InputError quoting the URI.
#include <gtest/gtest.h>

#include "core/base/errors.hpp"
#include "drivers/common/device_uri.hpp"

namespace plenopiv::drivers {
namespace {

std::string error_of(const std::string& text) {
  try {
    DeviceUri::parse(text);
  } catch (const InputError& e) {
    return e.what();
  }
  return "";
}

TEST(DeviceUri, ParsesSchemeTargetAndParameters) {
  const DeviceUri u = DeviceUri::parse("gpiod://gpiochip0?camera=27&qsync=5&");
  EXPECT_EQ(u.scheme(), "gpiod");
  EXPECT_EQ(u.target(), "gpiochip0");
  EXPECT_EQ(u.integer("camera"), 27);
  EXPECT_EQ(u.integer_or("qsync", 0), 5);
  EXPECT_EQ(u.integer_or("flashlamp1", -1), -1);
  const DeviceUri s = DeviceUri::parse("sim://?seed=1");
  EXPECT_EQ(s.target(), "");
  EXPECT_EQ(s.string_or("seed", ""), "1");
  EXPECT_EQ(DeviceUri::parse("aravis://Aravis-Fake-GV01").target(), "Aravis-Fake-GV01");
}

TEST(DeviceUri, MalformedOnesNameTheUriAndTheReason) {
  EXPECT_NE(error_of("gpiochip0").find("'gpiochip0': expected <scheme>://"), std::string::npos);
  EXPECT_NE(error_of("://x").find("scheme before :// is empty"), std::string::npos);
  EXPECT_NE(error_of("Aravis://x").find("scheme 'Aravis'"), std::string::npos);
  EXPECT_NE(error_of("sim://?seed").find("parameter 'seed' is not key=value"), std::string::npos);
  EXPECT_NE(error_of("sim://?seed=1&seed=2").find("'seed' is given twice"), std::string::npos);
  EXPECT_NE(error_of("sim://a b").find("contains ' '"), std::string::npos);
}

TEST(DeviceUri, TypedParametersAndUnknownKeys) {
  const DeviceUri u = DeviceUri::parse("gpiod://gpiochip0?camera=2x&rate=abc&typo=1");
  EXPECT_THROW(u.integer("camera"), InputError);
  EXPECT_THROW(u.number_or("rate", 1), InputError);
  EXPECT_THROW(u.integer("missing"), InputError);
  try {
    u.reject_unknown({"camera", "rate"});
    FAIL();
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("unknown parameter 'typo' (known: camera, rate)"), std::string::npos)
        << e.what();
  }
}

}  // namespace
}  // namespace plenopiv::drivers
