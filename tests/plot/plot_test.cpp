// Preview plots: the scale and tick choices as pure functions, and a preview PNG drawn with PLplot
// (right size, not blank, the colour map and the replaced-vector colour present), from threads at once.
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <set>
#include <thread>
#include <vector>

#include <opencv2/imgcodecs.hpp>

#include "core/base/errors.hpp"
#include "core/piv/peak_fit.hpp"
#include "core/plot/field_preview.hpp"
#include "core/plot/image_sheet.hpp"
#include "core/plot/scales.hpp"
#include "tests/support/temp_dir.hpp"

namespace plenopiv::plot {
namespace {

TEST(PlotScales, NiceStepIsOneTwoOrFiveTimesAPowerOfTen) {
  EXPECT_DOUBLE_EQ(nice_step(10, 5), 2);
  EXPECT_DOUBLE_EQ(nice_step(1000, 5), 200);
  EXPECT_DOUBLE_EQ(nice_step(1420, 3), 500);
  EXPECT_DOUBLE_EQ(nice_step(0.3, 6), 0.05);
  EXPECT_DOUBLE_EQ(nice_step(7, 10), 1);
  EXPECT_DOUBLE_EQ(nice_step(0, 5), 1);
  EXPECT_DOUBLE_EQ(nice_step(-3, 5), 1);
}

TEST(PlotScales, SymmetricScaleSpansTheDataWithRoundEnds) {
  // The example: a vorticity of +-1420 1/s reads -1500 .. 1500 in steps of 500.
  SymmetricScale s = symmetric_scale(1420);
  EXPECT_DOUBLE_EQ(s.limit, 1500);
  EXPECT_DOUBLE_EQ(s.step, 500);
  s = symmetric_scale(0.0123);
  EXPECT_DOUBLE_EQ(s.step, 0.005);
  EXPECT_DOUBLE_EQ(s.limit, 0.015);
  s = symmetric_scale(2000);  // exactly a step multiple: not widened
  EXPECT_DOUBLE_EQ(s.limit, 2000);
  for (double bad : {0.0, -1.0, std::nan(""), double(INFINITY)}) {
    s = symmetric_scale(bad);
    EXPECT_DOUBLE_EQ(s.limit, 1);
    EXPECT_DOUBLE_EQ(s.step, 1);
  }
}

TEST(PlotScales, TicksAreTheStepMultiplesInRange) {
  EXPECT_EQ(ticks(-1500, 1500, 500), (std::vector<double>{-1500, -1000, -500, 0, 500, 1000, 1500}));
  EXPECT_EQ(ticks(-2.3, 2.3, 1), (std::vector<double>{-2, -1, 0, 1, 2}));
  EXPECT_EQ(ticks(0.05, 0.25, 0.1).size(), 2u);
  EXPECT_TRUE(ticks(1, 0, 1).empty());
}

TEST(PlotScales, TickLabelsAreWrittenOutInFull) {
  EXPECT_EQ(tick_label(1500, 500), "1500");
  EXPECT_EQ(tick_label(-1000, 500), "-1000");
  EXPECT_EQ(tick_label(0.25, 0.05), "0.25");
  EXPECT_EQ(tick_label(0.1, 0.05), "0.10");
  EXPECT_EQ(tick_label(-1e-17, 0.1), "0.0");
  EXPECT_EQ(tick_label(-1e-13, 500), "0");
  EXPECT_EQ(tick_label(12000000, 2000000), "12000000");
  EXPECT_EQ(tick_label(0.0004, 0.0002), "0.0004");
}

TEST(PlotScales, ReferenceVectorIsTheRoundNumberNearestTheLongest) {
  EXPECT_DOUBLE_EQ(reference_length(0.37), 0.5);
  EXPECT_DOUBLE_EQ(reference_length(0.3), 0.2);
  EXPECT_DOUBLE_EQ(reference_length(0.5), 0.5);
  EXPECT_DOUBLE_EQ(reference_length(1.9), 2);
  EXPECT_DOUBLE_EQ(reference_length(12), 10);
  EXPECT_DOUBLE_EQ(reference_length(8), 10);
  EXPECT_DOUBLE_EQ(reference_length(0), 0);
  EXPECT_EQ(quantity_label(0.2, "m/s"), "0.2 m/s");
  EXPECT_EQ(quantity_label(20, "m/s"), "20 m/s");
  EXPECT_DOUBLE_EQ(arrow_scale(2.0, 0.5), 0.3);  // 2 m/s drawn 1.2 x 0.5 mm long
  EXPECT_DOUBLE_EQ(arrow_scale(0, 0.5), 0);
}

// A ring-like vortex about the z axis on a 15 x 11 x 5 grid, with replaced and missing vectors.
struct TestField {
  VectorField field;
  std::vector<std::uint8_t> flags;
};
TestField vortex_field() {
  Grid3 g;
  g.shape = {15, 11, 5};
  g.origin_mm = {-3.5, -2.5, -1.0};
  g.spacing_mm = {0.5, 0.5, 0.5};
  TestField t{VectorField(g), std::vector<std::uint8_t>(g.count(), 0)};
  t.field.dt_s = 50e-6;
  for (int k = 0; k < g.shape[2]; ++k)
    for (int j = 0; j < g.shape[1]; ++j)
      for (int i = 0; i < g.shape[0]; ++i) {
        const std::size_t n = g.index(i, j, k);
        const double x = g.coordinate_mm(0, i), y = g.coordinate_mm(1, j);
        const double r2 = x * x + y * y, swirl = 0.02 * std::exp(-r2 / 4);  // mm over dt
        t.field.dx_mm[n] = float(-y * swirl);
        t.field.dy_mm[n] = float(x * swirl);
        t.field.dz_mm[n] = float(0.01 * std::exp(-r2 / 2) - 0.004);
        t.field.valid[n] = 1;
        t.field.peak_ratio[n] = 3;
      }
  const int k = g.shape[2] / 2;
  for (int i : {2, 7, 11}) t.flags[g.index(i, 3, k)] = piv::flag_second_peak;
  t.flags[g.index(5, 8, k)] = piv::flag_interpolated;
  t.field.valid[g.index(0, 0, k)] = 0;
  t.field.valid[g.index(14, 10, k)] = 0;
  return t;
}

// Distinct colours of a BGR image and how many pixels are a given colour (within `tolerance` per channel).
std::set<std::uint32_t> colours_of(const cv::Mat& image) {
  std::set<std::uint32_t> out;
  for (int r = 0; r < image.rows; ++r)
    for (int c = 0; c < image.cols; ++c) {
      const auto p = image.at<cv::Vec3b>(r, c);
      out.insert(std::uint32_t(p[0]) << 16 | std::uint32_t(p[1]) << 8 | p[2]);
    }
  return out;
}
int pixels_near(const cv::Mat& image, cv::Vec3b bgr, int tolerance) {
  int count = 0;
  for (int r = 0; r < image.rows; ++r)
    for (int c = 0; c < image.cols; ++c) {
      const auto p = image.at<cv::Vec3b>(r, c);
      if (std::abs(p[0] - bgr[0]) <= tolerance && std::abs(p[1] - bgr[1]) <= tolerance &&
          std::abs(p[2] - bgr[2]) <= tolerance)
        ++count;
    }
  return count;
}

TEST(FieldPreview, WritesAPlotOfTheRequestedSizeWithItsColours) {
  const auto dir = testing_support::temp_dir("plot");
  const TestField t = vortex_field();
  const auto png = dir / "vortex.png";
  write_field_preview(png, t.field, t.flags, {1200, 560});
  const cv::Mat image = cv::imread(png.string(), cv::IMREAD_COLOR);
  ASSERT_FALSE(image.empty()) << png;
  EXPECT_EQ(image.cols, 1200);
  EXPECT_EQ(image.rows, 560);
  // Not blank: many colours (a colour map), mostly white paper.
  EXPECT_GT(colours_of(image).size(), 200u);
  EXPECT_GT(pixels_near(image, {255, 255, 255}, 0), 1200 * 560 / 4);
  // The diverging map's ends (blue negative w at the rim, red positive at the centre), the grey of
  // the two nodes without a vector, the green of the replaced vectors.
  EXPECT_GT(pixels_near(image, {97, 48, 5}, 40) + pixels_near(image, {195, 147, 67}, 30), 100);
  EXPECT_GT(pixels_near(image, {31, 0, 103}, 40) + pixels_near(image, {77, 96, 214}, 30), 100);
  EXPECT_GT(pixels_near(image, {190, 190, 190}, 2), 200);
  EXPECT_GT(pixels_near(image, {0, 170, 0}, 40), 20);
  EXPECT_FALSE(std::filesystem::exists(dir / "vortex.png.tmp"));
}

TEST(FieldPreview, WithoutReplacedVectorsNoneIsDrawnInTheirColour) {
  const auto dir = testing_support::temp_dir("plot");
  const TestField t = vortex_field();
  write_field_preview(dir / "plain.png", t.field, {});
  const cv::Mat image = cv::imread((dir / "plain.png").string(), cv::IMREAD_COLOR);
  ASSERT_FALSE(image.empty());
  EXPECT_EQ(image.cols, PreviewSize{}.width_px);
  EXPECT_EQ(image.rows, PreviewSize{}.height_px);
  // The key's sample arrow only.
  EXPECT_LT(pixels_near(image, {0, 170, 0}, 40), 60);
}

TEST(FieldPreview, ThreadsDrawingAtOnceEachGetTheirOwnImage) {
  const auto dir = testing_support::temp_dir("plot");
  const TestField t = vortex_field();
  std::vector<std::thread> threads;
  for (int i = 0; i < 4; ++i)
    threads.emplace_back([&, i] {
      write_field_preview(dir / ("thread-" + std::to_string(i) + ".png"), t.field, t.flags, {800, 400});
    });
  for (auto& th : threads) th.join();
  for (int i = 0; i < 4; ++i) {
    const cv::Mat image = cv::imread((dir / ("thread-" + std::to_string(i) + ".png")).string(), cv::IMREAD_COLOR);
    ASSERT_FALSE(image.empty()) << i;
    EXPECT_EQ(image.cols, 800);
    EXPECT_GT(colours_of(image).size(), 100u);
  }
}

TEST(FieldPreview, BadInputIsRefusedByName) {
  const auto dir = testing_support::temp_dir("plot");
  TestField t = vortex_field();
  const auto message = [&](const std::filesystem::path& png, const VectorField& f,
                           const std::vector<std::uint8_t>& flags) {
    try {
      write_field_preview(png, f, flags);
    } catch (const InputError& e) {
      return std::string(e.what());
    }
    return std::string("no error");
  };
  EXPECT_NE(message(dir / "missing-folder" / "p.png", t.field, t.flags).find("missing-folder does not exist"),
            std::string::npos);
  EXPECT_NE(message(dir / "p.png", t.field, {1, 2, 3}).find("flags has 3 values for 825 nodes"), std::string::npos);
  t.field.dt_s = 0;
  EXPECT_NE(message(dir / "p.png", t.field, t.flags).find("dt_s must be > 0"), std::string::npos);
  EXPECT_FALSE(std::filesystem::exists(dir / "p.png"));
}

// Five 40 x 30 images (a blob growing sharper) on one grey scale: a 3 x 2 grid of panels.
TEST(ImageSheet, PanelsOnOneGreyScale) {
  const auto dir = testing_support::temp_dir("plot");
  std::vector<ImageF> images;
  std::vector<std::string> labels;
  for (int k = 0; k < 5; ++k) {
    ImageF image(40, 30, 0.0f);
    const double width = 1.5 + 2.0 * (4 - k);
    for (int y = 0; y < 30; ++y)
      for (int x = 0; x < 40; ++x)
        image.at(x, y) = float(1000 * std::exp(-((x - 25) * (x - 25) + (y - 10) * (y - 10)) / (2 * width * width)));
    images.push_back(image);
    labels.push_back("z = " + std::to_string(k - 2) + " mm");
  }
  write_image_sheet(dir / "sheet.png", images, labels, "lens", 900);
  const cv::Mat image = cv::imread((dir / "sheet.png").string(), cv::IMREAD_COLOR);
  ASSERT_FALSE(image.empty());
  EXPECT_EQ(image.cols, 900);
  EXPECT_GT(image.rows, 300);
  EXPECT_GT(pixels_near(image, {0, 0, 0}, 10), 5000);            // the dark background of the images
  EXPECT_GT(pixels_near(image, {255, 255, 255}, 0), 900 * 100);  // the paper
  EXPECT_GT(colours_of(image).size(), 50u);                      // the grey levels
  EXPECT_THROW(write_image_sheet(dir / "bad.png", images, {"one"}, "lens"), InputError);
  EXPECT_THROW(write_image_sheet(dir / "bad.png", {}, {}, "lens"), InputError);
}

}  // namespace
}  // namespace plenopiv::plot
