// A tiny in-process camera for tests: deterministic images, pairs on demand, faults on request.
#include "tests/drivers/test_camera.hpp"

#include <array>
#include <cstdio>
#include <sstream>

namespace plenopiv::testing_support {

using namespace plenopiv::drivers;

TestCamera::TestCamera(std::string uri, TestCameraFaults faults, bool with_input, TestCameraSensor sensor)
    : CameraBase(CameraInfo{uri, "plenopiv", "test camera", "T0", sensor.width, sensor.height, "burst (test)"},
                 PairerOptions{2'000'000, 0, 1'000'000'000}),
      faults_(std::move(faults)),
      with_input_(with_input),
      sensor_(sensor) {}

std::uint16_t TestCamera::test_pixel(std::uint64_t frame_id, int x, int y) {
  return std::uint16_t((frame_id * 131 + std::uint64_t(x) * 7 + std::uint64_t(y) * 3) & 0x0fff);
}

void TestCamera::do_configure(const CameraSettings& settings) { settings_ = settings; }

void TestCamera::fire() {
  const int w = settings_.roi.width > 0 ? settings_.roi.width : sensor_.width;
  const int h = settings_.roi.height > 0 ? settings_.roi.height : sensor_.height;
  // Both frames are made before either is delivered, as a camera reads B out one read-out after A:
  // filling a large sensor (slow under a sanitizer) must not hold A back past the pairer's wait.
  std::array<Frame, 2> frames;
  for (int k = 0; k < 2; ++k) {
    Frame& f = frames[std::size_t(k)];
    f.frame_id = next_id_++;
    f.device_timestamp_ns = trigger_ * 100'000'000 + std::uint64_t(k) * 1'000'000 + 1;
    f.bit_depth = bit_depth(settings_.pixel_format);
    f.image = ImageU16(w, h);
    for (int y = 0; y < h; ++y)
      for (int x = 0; x < w; ++x) f.image.at(x, y) = test_pixel(f.frame_id, x, y);
  }
  for (Frame& f : frames) {
    const std::uint64_t number = frame_number_++;
    if (faults_.lose.count(number)) continue;
    f.complete = faults_.incomplete.count(number) == 0;
    if (!f.complete) f.image = ImageU16();
    f.host_timestamp_ns = host_now_ns();  // arrival at the host
    submit_frame(std::move(f));
  }
  ++trigger_;
}

namespace {
std::set<std::uint64_t> numbers(const std::string& list) {
  std::set<std::uint64_t> out;
  std::stringstream s(list);
  std::string item;
  while (std::getline(s, item, ',')) out.insert(std::stoull(item));
  return out;
}
}  // namespace

void register_test_camera(CameraRegistry& registry) {
  registry.add("test", [](const DeviceUri& uri) -> std::unique_ptr<Camera> {
    uri.reject_unknown({"lose", "incomplete", "input", "sensor"});
    const std::string input = uri.string_or("input", "line");
    if (input != "line" && input != "none") uri.fail("input: line or none, got '" + input + "'");
    TestCameraFaults faults{numbers(uri.string_or("lose", "")), numbers(uri.string_or("incomplete", ""))};
    TestCameraSensor sensor;
    const std::string size = uri.string_or("sensor", "64x48");
    if (std::sscanf(size.c_str(), "%dx%d", &sensor.width, &sensor.height) != 2 || sensor.width < 1 || sensor.height < 1)
      uri.fail("sensor: WxH in px, got '" + size + "'");
    return std::make_unique<TestCamera>(uri.text(), faults, input == "line", sensor);
  });
}

}  // namespace plenopiv::testing_support
