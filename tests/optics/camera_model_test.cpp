// Camera model: thin-lens geometry, f-number matching (eq 7) and every refused camera file.
#include <gtest/gtest.h>

#include <cmath>
#include <string>

#include "core/base/errors.hpp"
#include "core/optics/camera_file.hpp"
#include "core/optics/microlens_array.hpp"

namespace plenopiv::optics {
namespace {

const std::string kPaper = R"(
sensor:    {width_px: 4904, height_px: 3280, pixel_pitch_mm: 0.0074}
microlens: {pitch_mm: 0.125, focal_length_mm: 0.5, count_x: 289, count_y: 193, layout: rect}
main_lens: {focal_length_mm: 50, f_number: 2, magnification: -1}
)";

// Replaces the first occurrence of `from` in the paper's file with `to`.
std::string paper_with(const std::string& from, const std::string& to) {
  std::string text = kPaper;
  const auto at = text.find(from);
  EXPECT_NE(at, std::string::npos) << from;
  return text.replace(at, from.size(), to);
}

// The message of the InputError that parsing `text` throws ("" if none).
std::string error_of(const std::string& text) {
  try {
    parse_camera_yaml(text, "cam.yaml");
  } catch (const InputError& e) {
    return e.what();
  }
  return "";
}

TEST(CameraModel, PaperConfigurationGivesTablesOneAndTwo) {
  const CameraModel cam = parse_camera_yaml(kPaper, "paper");
  EXPECT_NEAR(cam.image_distance_mm(), 100.0, 1e-12);   // table 2: s_i
  EXPECT_NEAR(cam.object_distance_mm(), 100.0, 1e-12);  // table 2: s_o
  EXPECT_NEAR(cam.pixels_per_microlens(), 0.125 / 0.0074, 1e-12);
  EXPECT_NEAR(cam.pixels_per_microlens(), 16.89, 0.01);  // sec 3.2
  EXPECT_NEAR(cam.microlens_f_number(), 4.0, 1e-12);
  EXPECT_NEAR(cam.image_side_f_number(), 4.0, 1e-12);
  EXPECT_NEAR(cam.matched_main_f_number(), 2.0, 1e-12);  // eq 7
  EXPECT_NEAR(cam.aperture_diameter_mm(), 25.0, 1e-12);
  EXPECT_NEAR(cam.microlens_image_diameter_px(), cam.pixels_per_microlens(), 1e-9);
  EXPECT_NEAR(cam.field_of_view_x_mm(), 289 * 0.125, 1e-9);
  EXPECT_NEAR(cam.field_of_view_y_mm(), 193 * 0.125, 1e-9);
  EXPECT_NEAR(cam.nominal_voxel_size_mm(), 0.125, 1e-12);  // sec 6.1
  EXPECT_TRUE(cam.notes().empty());
}

TEST(CameraModel, ThinLensAtOtherMagnifications) {
  // M = -0.5 with f = 50: s_i = f (1 - M) = 75, s_o = f (1 - 1/M) = 150; 1/75 + 1/150 = 1/50.
  const CameraModel cam = parse_camera_yaml(
      paper_with("magnification: -1", "magnification: -0.5").replace(kPaper.find("f_number: 2"), 11, "f_number: 2.667"),
      "m05");
  EXPECT_NEAR(cam.image_distance_mm(), 75.0, 1e-9);
  EXPECT_NEAR(cam.object_distance_mm(), 150.0, 1e-9);
  EXPECT_NEAR(1 / cam.image_distance_mm() + 1 / cam.object_distance_mm(), 1 / 50.0, 1e-12);
  EXPECT_NEAR(cam.nominal_voxel_size_mm(), 0.25, 1e-12);
}

// Eq 7 is checked against the camera file's nominal f-number: a faster lens predicts overlapping
// micro-images, which only a white image can confirm (calibration refuses real overlap), so the
// camera file gets a note with the predicted fill, not a refusal.
TEST(CameraModel, FNumberMatchingNotesAFasterLensAndASlowerOne) {
  EXPECT_TRUE(parse_camera_yaml(kPaper, "paper").notes().empty());
  const CameraModel fast = parse_camera_yaml(paper_with("f_number: 2", "f_number: 1.4"), "fast");
  ASSERT_EQ(fast.notes().size(), 1u);
  EXPECT_NE(fast.notes()[0].find("main lens f/1.4"), std::string::npos) << fast.notes()[0];
  EXPECT_NE(fast.notes()[0].find("overlap"), std::string::npos) << fast.notes()[0];
  EXPECT_NE(fast.notes()[0].find("eq 7 matches at f/2"), std::string::npos) << fast.notes()[0];
  EXPECT_NEAR(fast.predicted_fill(), 2 / 1.4 / 1.005, 1e-9);  // diameter over the spot pitch
  EXPECT_NE(fast.summary().find("fill 142.146 % of the spot pitch"), std::string::npos) << fast.summary();
  // A slower lens is legal but leaves each microlens image underfilled: a note, not an error.
  const CameraModel slow = parse_camera_yaml(paper_with("f_number: 2", "f_number: 2.8"), "slow");
  ASSERT_EQ(slow.notes().size(), 1u);
  EXPECT_NE(slow.notes()[0].find("slower than the matched f/2"), std::string::npos);
  EXPECT_LT(slow.microlens_image_diameter_px(), slow.pixels_per_microlens());
}

TEST(CameraModel, HexLayoutUsesRowPitchAndHalfLensShift) {
  const CameraModel cam = parse_camera_yaml(
      paper_with("layout: rect", "layout: hex").replace(kPaper.find("count_y: 193"), 12, "count_y: 200"), "hex");
  EXPECT_EQ(cam.microlens().layout, LensletLayout::hex);
  EXPECT_NEAR(cam.row_pitch_mm(), 0.125 * std::sqrt(3.0) / 2, 1e-12);
  EXPECT_NEAR(cam.array_width_mm(), 289.5 * 0.125, 1e-12);
  EXPECT_NEAR(cam.array_height_mm(), 199 * cam.row_pitch_mm() + 0.125, 1e-12);
}

TEST(CameraFile, ShippedDefaultIsThePaperCamera) {
  const CameraModel cam =
      load_camera_file(std::string(PLENOPIV_SOURCE_DIR) + "/systemd/config/camera-fahringer2015.yaml");
  EXPECT_EQ(cam.sensor().width_px, 4904);
  EXPECT_EQ(cam.microlens().count_y, 193);
  EXPECT_NEAR(cam.image_distance_mm(), 100.0, 1e-12);
  const CameraModel small = load_camera_file(std::string(PLENOPIV_SOURCE_DIR) + "/systemd/config/camera-small.yaml");
  EXPECT_EQ(small.lens_count(), 2500);
}

TEST(CameraFile, RoundTripsThroughYaml) {
  const CameraModel cam = parse_camera_yaml(kPaper, "paper");
  const CameraModel again = parse_camera_yaml(to_yaml(cam.spec()), "again");
  EXPECT_EQ(again.sensor().width_px, cam.sensor().width_px);
  EXPECT_DOUBLE_EQ(again.sensor().pixel_pitch_mm, cam.sensor().pixel_pitch_mm);
  EXPECT_DOUBLE_EQ(again.microlens().pitch_mm, cam.microlens().pitch_mm);
  EXPECT_DOUBLE_EQ(again.main_lens().magnification, cam.main_lens().magnification);
}

struct BadCase {
  const char* name;
  std::string text;
  std::vector<std::string> expected;  // fragments the message must contain
};

class CameraFileRefuses : public testing::TestWithParam<BadCase> {};

TEST_P(CameraFileRefuses, WithAMessageNamingKeyAndReason) {
  const BadCase& c = GetParam();
  const std::string err = error_of(c.text);
  ASSERT_FALSE(err.empty()) << c.name << " was accepted";
  EXPECT_EQ(err.rfind("cam.yaml: ", 0), 0u) << err;
  for (const std::string& fragment : c.expected) {
    EXPECT_NE(err.find(fragment), std::string::npos) << "'" << fragment << "' not in: " << err;
  }
}

INSTANTIATE_TEST_SUITE_P(
    Cases, CameraFileRefuses,
    testing::Values(
        BadCase{"missing_key", paper_with("focal_length_mm: 0.5, ", ""), {"microlens.focal_length_mm", "missing"}},
        BadCase{"one_count_only", paper_with("count_x: 289, ", ""), {"microlens.count_x", "both counts or neither"}},
        BadCase{"axis_off_the_sensor",
                paper_with("pixel_pitch_mm: 0.0074}", "pixel_pitch_mm: 0.0074, optical_axis_px: [5000, 10]}"),
                {"sensor.optical_axis_px", "not on the sensor", "[2451.5, 1639.5]"}},
        BadCase{"axis_not_a_pair",
                paper_with("pixel_pitch_mm: 0.0074}", "pixel_pitch_mm: 0.0074, optical_axis_px: 2451.5}"),
                {"sensor.optical_axis_px", "[column, row]"}},
        BadCase{"axis_not_numbers",
                paper_with("pixel_pitch_mm: 0.0074}", "pixel_pitch_mm: 0.0074, optical_axis_px: [middle, 3]}"),
                {"sensor.optical_axis_px", "'middle'"}},
        BadCase{"missing_section",
                "sensor: {width_px: 4904, height_px: 3280, pixel_pitch_mm: 0.0074}\n"
                "microlens: {pitch_mm: 0.125, focal_length_mm: 0.5, count_x: 289, count_y: 193}\n",
                {"main_lens", "missing"}},
        BadCase{"wrong_type",
                paper_with("width_px: 4904", "width_px: wide"),
                {"sensor.width_px", "expected a whole number in pixels", "'wide'"}},
        BadCase{"unit_in_value",
                paper_with("pitch_mm: 0.125", "pitch_mm: 0.125 mm"),
                {"microlens.pitch_mm", "expected a number in millimetres", "'0.125 mm'"}},
        BadCase{
            "wrong_unit_key", paper_with("pitch_mm: 0.125", "pitch_um: 125"), {"microlens.pitch_um", "unknown key"}},
        BadCase{"negative_pitch",
                paper_with("pitch_mm: 0.125", "pitch_mm: -0.125"),
                {"microlens.pitch_mm", "positive", "-0.125"}},
        BadCase{"zero_pixel_pitch",
                paper_with("pixel_pitch_mm: 0.0074", "pixel_pitch_mm: 0"),
                {"sensor.pixel_pitch_mm", "positive"}},
        BadCase{"magnification_zero",
                paper_with("magnification: -1", "magnification: 0"),
                {"main_lens.magnification", "non-zero"}},
        BadCase{"magnification_positive",
                paper_with("magnification: -1", "magnification: 1"),
                {"main_lens.magnification", "negative"}},
        BadCase{
            "bad_layout", paper_with("layout: rect", "layout: square"), {"microlens.layout", "rect, hex", "'square'"}},
        BadCase{"count_not_whole", paper_with("count_x: 289", "count_x: 28.9"), {"microlens.count_x", "whole number"}},
        BadCase{"section_not_map",
                paper_with("main_lens: {focal_length_mm: 50, f_number: 2, magnification: -1}", "main_lens: 50"),
                {"main_lens", "expected a mapping"}},
        BadCase{"not_yaml", "sensor: {width_px: 4904\n", {"not valid YAML"}},
        BadCase{"lens_smaller_than_two_pixels",
                paper_with("pitch_mm: 0.125", "pitch_mm: 0.01"),
                {"microlens.pitch_mm", "at least 2 pixels"}}),
    [](const testing::TestParamInfo<BadCase>& info) { return std::string(info.param.name); });

// Real arrays overfill the sensor, and their lens counts are often unknown: counts are optional,
// and an array larger than the sensor is described, its nominal part the lenses the sensor holds.
TEST(CameraFile, CountsAreOptionalAndAnArrayMayOverfillTheSensor) {
  const CameraModel without = parse_camera_yaml(paper_with("count_x: 289, count_y: 193, ", ""), "no counts");
  EXPECT_FALSE(without.counts_given());
  EXPECT_EQ(without.nominal_count_x(), 290);  // 4904 x 7.4 um / 125 um = 290.3 lenses
  EXPECT_EQ(without.nominal_count_y(), 194);
  EXPECT_TRUE(without.notes().empty());
  EXPECT_NE(without.summary().find("fit on the sensor (counts not given)"), std::string::npos);
  const CameraModel again = parse_camera_yaml(to_yaml(without.spec()), "again");
  EXPECT_FALSE(again.counts_given());

  const CameraModel over = parse_camera_yaml(paper_with("count_x: 289", "count_x: 300"), "overfilling");
  EXPECT_EQ(over.microlens().count_x, 300);
  EXPECT_EQ(over.nominal_count_x(), 290);
  EXPECT_EQ(over.nominal_count_y(), 193);
  ASSERT_EQ(over.notes().size(), 1u);
  EXPECT_NE(over.notes()[0].find("300 x 193 lenses overfills"), std::string::npos) << over.notes()[0];
  EXPECT_EQ(Lattice::nominal(over).count_x, 290);
  EXPECT_NEAR(over.field_of_view_x_mm(), 290 * 0.125, 1e-9);
}

// The optical axis is the origin of sensor-plane millimetres: given, it moves every mapping.
TEST(CameraFile, OpticalAxisIsTheOriginOfTheSensorPlane) {
  const CameraModel centred = parse_camera_yaml(kPaper, "paper");
  EXPECT_FALSE(centred.sensor().optical_axis_px);
  EXPECT_EQ(centred.optical_axis_px()[0], 2451.5);
  EXPECT_EQ(centred.optical_axis_px()[1], 1639.5);
  const CameraModel off = parse_camera_yaml(
      paper_with("pixel_pitch_mm: 0.0074}", "pixel_pitch_mm: 0.0074, optical_axis_px: [2457.5, 1635.25]}"), "off");
  ASSERT_TRUE(off.sensor().optical_axis_px);
  const SensorSpec& s = off.sensor();
  EXPECT_NEAR(column_to_sensor_mm(s, 2457.5), 0.0, 1e-15);
  EXPECT_NEAR(row_to_sensor_mm(s, 1635.25), 0.0, 1e-15);
  EXPECT_NEAR(column_to_sensor_mm(s, 2467.5), 10 * 0.0074, 1e-12);
  EXPECT_NEAR(sensor_mm_to_column(s, column_to_sensor_mm(s, 123.25)), 123.25, 1e-9);
  EXPECT_NEAR(sensor_mm_to_row(s, row_to_sensor_mm(s, 7.5)), 7.5, 1e-9);
  // Without the key the origin is the sensor centre, by the same formula as always.
  EXPECT_NEAR(column_to_sensor_mm(centred.sensor(), 2451.5), 0.0, 1e-15);
  const CameraModel again = parse_camera_yaml(to_yaml(off.spec()), "again");
  ASSERT_TRUE(again.sensor().optical_axis_px);
  EXPECT_EQ((*again.sensor().optical_axis_px)[0], 2457.5);
  EXPECT_EQ((*again.sensor().optical_axis_px)[1], 1635.25);
  EXPECT_NE(off.summary().find("optical axis  column 2457.5, row 1635.25\n"), std::string::npos) << off.summary();
}

TEST(CameraFile, UnreadableFileIsNamed) {
  try {
    load_camera_file("/nonexistent/camera.yaml");
    FAIL() << "no error";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("/nonexistent/camera.yaml: cannot open"), std::string::npos);
  }
}
}  // namespace
}  // namespace plenopiv::optics

namespace plenopiv::optics {
namespace {

TEST(MicrolensArray, NominalLatticeIsCentredOnTheSensor) {
  const CameraModel cam = parse_camera_yaml(kPaper, "paper");
  const MicrolensArray array = MicrolensArray::from_lattice(Lattice::nominal(cam));
  ASSERT_EQ(array.centres_mm.size(), std::size_t(289 * 193));
  const auto first = array.centre(0, 0);
  const auto last = array.centre(288, 192);
  EXPECT_NEAR(first[0], -last[0], 1e-12);
  EXPECT_NEAR(first[1], -last[1], 1e-12);
  EXPECT_NEAR(array.centre(144, 96)[0], 0.0, 1e-12);  // odd counts: the middle lens is on axis
  EXPECT_NEAR(array.centre(145, 96)[0] - array.centre(144, 96)[0], 0.125, 1e-12);
}

TEST(MicrolensArray, RotationTurnsPlusXTowardsMinusYOnTheUprightImage) {
  Lattice l;
  l.count_x = 3;
  l.count_y = 1;
  l.pitch_x_mm = l.pitch_y_mm = 1.0;
  l.rotation_rad = std::acos(-1.0) / 2;
  const auto p = l.position(2, 0);  // one pitch right of the centre before rotation
  EXPECT_NEAR(p[0], 0.0, 1e-12);
  EXPECT_NEAR(p[1], -1.0, 1e-12);
}

TEST(MicrolensArray, HexRowsAreShiftedByHalfAPitch) {
  Lattice l;
  l.layout = LensletLayout::hex;
  l.count_x = 4;
  l.count_y = 2;
  l.pitch_x_mm = 1.0;
  l.pitch_y_mm = std::sqrt(3.0) / 2;
  EXPECT_NEAR(l.position(0, 1)[0] - l.position(0, 0)[0], 0.5, 1e-12);
  EXPECT_NEAR(l.position(0, 1)[1] - l.position(0, 0)[1], std::sqrt(3.0) / 2, 1e-12);
}

TEST(SensorGeometry, PixelCentresAndTheApertureMapping) {
  const CameraModel cam = parse_camera_yaml(kPaper, "paper");
  const SensorSpec& s = cam.sensor();
  EXPECT_NEAR(column_to_sensor_mm(s, 0), (0.5 - 2452) * 0.0074, 1e-12);
  EXPECT_NEAR(sensor_mm_to_column(s, column_to_sensor_mm(s, 123.25)), 123.25, 1e-9);
  EXPECT_NEAR(sensor_mm_to_row(s, row_to_sensor_mm(s, 7.5)), 7.5, 1e-9);
  // The spot of a lens 10 mm off axis sits f_l / s_i further out; u = 0 there.
  const double spot = lens_centre_to_spot_mm(10.0, 100.0, 0.5);
  EXPECT_NEAR(spot, 10.05, 1e-12);
  EXPECT_NEAR(spot_to_lens_centre_mm(spot, 100.0, 0.5), 10.0, 1e-12);
  EXPECT_NEAR(aperture_from_sensor_mm(spot, spot, 100.0, 0.5), 0.0, 1e-12);
  // Half a pitch right of the spot sees the left edge of a matched aperture: u = -p_m / 2.
  EXPECT_NEAR(aperture_from_sensor_mm(spot + 0.0625, spot, 100.0, 0.5), -12.5, 1e-9);
}

// Binning keeps the optics and the sensor's extent in mm; each binned pixel sits at the mean of
// the raw pixels it reads, in sensor mm, with the optical axis at the centre or where a camera file
// (or calibration) put it.
TEST(CameraModel, ABinnedCameraKeepsItsGeometryInMillimetres) {
  for (const std::string& axis : {std::string(), std::string(", optical_axis_px: [2440.3, 1651.8]")}) {
    const CameraModel raw =
        parse_camera_yaml(paper_with("pixel_pitch_mm: 0.0074", "pixel_pitch_mm: 0.0074" + axis), "paper");
    for (int factor : {1, 2, 4}) {
      const CameraModel b = raw.binned(factor);
      EXPECT_EQ(b.sensor().width_px, 4904 / factor);
      EXPECT_EQ(b.sensor().height_px, 3280 / factor);
      EXPECT_DOUBLE_EQ(b.sensor().pixel_pitch_mm, 0.0074 * factor);
      EXPECT_NEAR(b.sensor_width_mm(), raw.sensor_width_mm(), 1e-12);
      EXPECT_NEAR(b.pixels_per_microlens(), raw.pixels_per_microlens() / factor, 1e-12);
      EXPECT_NEAR(b.microlens_image_diameter_px(), raw.microlens_image_diameter_px() / factor, 1e-12);
      EXPECT_EQ(b.nominal_count_x(), raw.nominal_count_x());
      EXPECT_EQ(b.nominal_count_y(), raw.nominal_count_y());
      EXPECT_DOUBLE_EQ(b.image_distance_mm(), raw.image_distance_mm());
      for (int k : {0, 7, 1000, 4904 / factor - 1}) {
        double mean_x = 0, mean_y = 0;
        for (int r = 0; r < factor; ++r) {
          mean_x += column_to_sensor_mm(raw.sensor(), factor * k + r) / factor;
          mean_y += row_to_sensor_mm(raw.sensor(), factor * (k % 820) + r) / factor;
        }
        EXPECT_NEAR(column_to_sensor_mm(b.sensor(), k), mean_x, 1e-12) << factor << axis;
        EXPECT_NEAR(row_to_sensor_mm(b.sensor(), k % 820), mean_y, 1e-12) << factor << axis;
      }
    }
  }
  const CameraModel raw = parse_camera_yaml(kPaper, "paper");
  for (int bad : {0, -2, 3, 5}) {  // 4904 = 2^3 x 613 and 3280 = 2^4 x 5 x 41: 5 divides the height only
    try {
      raw.binned(bad);
      ADD_FAILURE() << bad << " accepted";
    } catch (const InputError& e) {
      EXPECT_NE(std::string(e.what()).find("pixel binning " + std::to_string(bad) +
                                           " does not divide the sensor's "
                                           "4904 x 3280 px"),
                std::string::npos)
          << e.what();
    }
  }
}

}  // namespace
}  // namespace plenopiv::optics
