// The calibration file in HDF5: written atomically, read back with every part checked.
#include "core/calib/calibration_file.hpp"

#include <hdf5.h>

#include <array>
#include <cmath>
#include <string>
#include <vector>

#include "core/base/errors.hpp"
#include "core/io/atomic_file.hpp"
#include "core/io/hdf5_handle.hpp"

namespace plenopiv::calib {
namespace {

using Handle = io::Hdf5Handle;

struct File {
  std::filesystem::path path;
  std::string where(const std::string& what) const { return path.string() + ": " + what; }
};

void write_set(const File& f, hid_t parent, const std::string& name, const std::vector<hsize_t>& dims, hid_t file_type,
               hid_t mem_type, const void* data) {
  Handle space(H5Screate_simple(int(dims.size()), dims.data(), nullptr), H5Sclose);
  Handle set(H5Dcreate2(parent, name.c_str(), file_type, space.get(), H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT), H5Dclose);
  if (!set.ok() || H5Dwrite(set.get(), mem_type, H5S_ALL, H5S_ALL, H5P_DEFAULT, data) < 0) {
    throw InputError(f.where("HDF5: cannot write dataset " + name));
  }
}

void write_attr(const File& f, hid_t parent, const std::string& name, double value) {
  Handle space(H5Screate(H5S_SCALAR), H5Sclose);
  Handle attr(H5Acreate2(parent, name.c_str(), H5T_IEEE_F64LE, space.get(), H5P_DEFAULT, H5P_DEFAULT), H5Aclose);
  if (!attr.ok() || H5Awrite(attr.get(), H5T_NATIVE_DOUBLE, &value) < 0) {
    throw InputError(f.where("HDF5: cannot write attribute " + name));
  }
}

double read_attr(const File& f, hid_t parent, const std::string& group, const std::string& name) {
  if (H5Aexists(parent, name.c_str()) <= 0) throw InputError(f.where("/" + group + " has no attribute " + name));
  Handle attr(H5Aopen(parent, name.c_str(), H5P_DEFAULT), H5Aclose);
  Handle space(H5Aget_space(attr.get()), H5Sclose);
  double value = 0;
  if (H5Sget_simple_extent_npoints(space.get()) != 1 || H5Aread(attr.get(), H5T_NATIVE_DOUBLE, &value) < 0) {
    throw InputError(f.where("/" + group + " attribute " + name + " is not one number"));
  }
  return value;
}

// An attribute added after the first files were written: `fallback` when an older file lacks it.
double read_attr_or(const File& f, hid_t parent, const std::string& group, const std::string& name, double fallback) {
  if (H5Aexists(parent, name.c_str()) <= 0) return fallback;
  return read_attr(f, parent, group, name);
}

template <typename T, typename Array = std::vector<T>>
Array read_set(const File& f, hid_t parent, const std::string& name, const std::vector<hsize_t>& expected,
               hid_t mem_type) {
  if (H5Lexists(parent, name.c_str(), H5P_DEFAULT) <= 0) throw InputError(f.where("no dataset /" + name));
  Handle set(H5Dopen2(parent, name.c_str(), H5P_DEFAULT), H5Dclose);
  Handle space(H5Dget_space(set.get()), H5Sclose);
  std::vector<hsize_t> dims(std::max(0, H5Sget_simple_extent_ndims(space.get())));
  H5Sget_simple_extent_dims(space.get(), dims.data(), nullptr);
  if (dims != expected) {
    std::string shape;
    for (hsize_t d : expected) shape += "[" + std::to_string(d) + "]";
    throw InputError(f.where("dataset /" + name + " does not have the shape " + shape));
  }
  std::size_t n = 1;
  for (hsize_t d : dims) n *= d;
  Array data(n);
  if (H5Dread(set.get(), mem_type, H5S_ALL, H5S_ALL, H5P_DEFAULT, data.data()) < 0) {
    throw InputError(f.where("cannot read dataset /" + name));
  }
  return data;
}

std::vector<double> flatten(const std::vector<std::array<double, 2>>& v) {
  std::vector<double> out;
  out.reserve(2 * v.size());
  for (const auto& q : v) {
    out.push_back(q[0]);
    out.push_back(q[1]);
  }
  return out;
}

std::vector<std::array<double, 2>> pairs(const std::vector<double>& v) {
  std::vector<std::array<double, 2>> out(v.size() / 2);
  for (std::size_t k = 0; k < out.size(); ++k) out[k] = {v[2 * k], v[2 * k + 1]};
  return out;
}

}  // namespace

void write_calibration_h5(const std::filesystem::path& path, const Calibration& cal) {
  const File f{path};
  const hsize_t nx = hsize_t(cal.spot_lattice.count_x), ny = hsize_t(cal.spot_lattice.count_y);
  if (cal.spots_px.size() != nx * ny || cal.status.size() != nx * ny || cal.residuals_px.size() != nx * ny) {
    throw InputError(f.where("calibration arrays do not match the lattice size"));
  }
  if (cal.white_correction.width != cal.sensor.width_px || cal.white_correction.height != cal.sensor.height_px) {
    throw InputError(f.where("the white correction is missing or not the sensor's size"));
  }
  const optics::MicrolensArray lenses = cal.microlens_array();
  const double pp = cal.sensor.pixel_pitch_mm;
  io::write_atomically(path, [&](const std::filesystem::path& tmp) {
    Handle file(H5Fcreate(tmp.c_str(), H5F_ACC_TRUNC, H5P_DEFAULT, H5P_DEFAULT), H5Fclose);
    if (!file.ok()) throw InputError(f.where("cannot create HDF5 file"));
    const hid_t root = file.get();
    write_set(f, root, "spots_px", {ny, nx, 2}, H5T_IEEE_F64LE, H5T_NATIVE_DOUBLE, flatten(cal.spots_px).data());
    write_set(f, root, "lens_centres_mm", {ny, nx, 2}, H5T_IEEE_F64LE, H5T_NATIVE_DOUBLE,
              flatten(lenses.centres_mm).data());
    write_set(f, root, "residuals_px", {ny, nx, 2}, H5T_IEEE_F64LE, H5T_NATIVE_DOUBLE,
              flatten(cal.residuals_px).data());
    std::vector<std::uint8_t> status(cal.status.size());
    for (std::size_t k = 0; k < status.size(); ++k) status[k] = std::uint8_t(cal.status[k]);
    write_set(f, root, "status", {ny, nx}, H5T_STD_U8LE, H5T_NATIVE_UINT8, status.data());
    write_set(f, root, "white_correction", {hsize_t(cal.sensor.height_px), hsize_t(cal.sensor.width_px)},
              H5T_IEEE_F32LE, H5T_NATIVE_FLOAT, cal.white_correction.pixels.data());
    const double nan = std::nan("");
    std::vector<std::array<double, 2>> measured = cal.measured_px;
    std::vector<double> uncertainty = cal.uncertainty_px;
    measured.resize(nx * ny, {nan, nan});
    uncertainty.resize(nx * ny, nan);
    write_set(f, root, "measured_px", {ny, nx, 2}, H5T_IEEE_F64LE, H5T_NATIVE_DOUBLE, flatten(measured).data());
    write_set(f, root, "uncertainty_px", {ny, nx}, H5T_IEEE_F64LE, H5T_NATIVE_DOUBLE, uncertainty.data());

    Handle lattice(H5Gcreate2(root, "lattice", H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT), H5Gclose);
    const optics::Lattice& sl = cal.spot_lattice;
    const hid_t g = lattice.get();
    write_attr(f, g, "layout", sl.layout == optics::LensletLayout::hex ? 1 : 0);
    write_attr(f, g, "count_x", sl.count_x);
    write_attr(f, g, "count_y", sl.count_y);
    write_attr(f, g, "spot_pitch_x_px", sl.pitch_x_mm / pp);
    write_attr(f, g, "spot_pitch_y_px", sl.pitch_y_mm / pp);
    write_attr(f, g, "rotation_rad", sl.rotation_rad);
    write_attr(f, g, "spot_offset_x_px", sl.offset_x_mm / pp);
    write_attr(f, g, "spot_offset_y_px", sl.offset_y_mm / pp);
    write_attr(f, g, "lens_pitch_x_mm", lenses.lattice.pitch_x_mm);
    write_attr(f, g, "lens_pitch_y_mm", lenses.lattice.pitch_y_mm);
    write_attr(f, g, "lens_offset_x_mm", lenses.lattice.offset_x_mm);
    write_attr(f, g, "lens_offset_y_mm", lenses.lattice.offset_y_mm);
    write_attr(f, g, "rms_residual_px", cal.rms_residual_px);
    write_attr(f, g, "max_residual_px", cal.max_residual_px);
    write_attr(f, g, "spots_found", cal.spots_found);
    write_attr(f, g, "lenses_measured", cal.lenses_measured);
    write_attr(f, g, "lenses_lattice", cal.lenses_lattice);
    write_attr(f, g, "lenses_partial", cal.lenses_partial);
    write_attr(f, g, "lenses_rejected", cal.lenses_rejected);
    write_attr(f, g, "lenses_vignetted", cal.lenses_vignetted);
    write_attr(f, g, "centres_from", cal.source == CentreSource::white ? 1 : 0);
    write_attr(f, g, "measurement_scatter_px", cal.measurement_scatter_px);
    write_attr(f, g, "array_scatter_px", cal.array_scatter_px);
    write_attr(f, g, "distortion_degree", cal.distortion_degree);
    write_attr(f, g, "nominal_spot_pitch_px", cal.nominal_spot_pitch_px);
    write_attr(f, g, "pitch_ratio", cal.pitch_ratio);

    Handle camera(H5Gcreate2(root, "camera", H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT), H5Gclose);
    write_attr(f, camera.get(), "sensor_width_px", cal.sensor.width_px);
    write_attr(f, camera.get(), "sensor_height_px", cal.sensor.height_px);
    write_attr(f, camera.get(), "pixel_pitch_mm", pp);
    write_attr(f, camera.get(), "image_distance_mm", cal.image_distance_mm);
    write_attr(f, camera.get(), "microlens_focal_length_mm", cal.microlens_focal_length_mm);
    write_attr(f, camera.get(), "optical_axis_given", cal.sensor.optical_axis_px ? 1 : 0);
    write_attr(f, camera.get(), "optical_axis_measured", cal.axis_measured ? 1 : 0);
    write_attr(f, camera.get(), "optical_axis_x_px", optics::sensor_mm_to_column(cal.sensor, 0.0));
    write_attr(f, camera.get(), "optical_axis_y_px", optics::sensor_mm_to_row(cal.sensor, 0.0));
    write_attr(f, camera.get(), "camera_count_x", cal.camera_count_x);
    write_attr(f, camera.get(), "camera_count_y", cal.camera_count_y);

    Handle image(H5Gcreate2(root, "image", H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT), H5Gclose);
    write_attr(f, image.get(), "background", cal.image_stats.background);
    write_attr(f, image.get(), "noise_sigma", cal.image_stats.noise_sigma);
    write_attr(f, image.get(), "threshold", cal.image_stats.threshold);
    write_attr(f, image.get(), "hot_pixels", cal.image_stats.hot_pixels);

    Handle white(H5Gcreate2(root, "white", H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT), H5Gclose);
    write_attr(f, white.get(), "fill", cal.fill);
    write_attr(f, white.get(), "predicted_fill", cal.predicted_fill);
    write_attr(f, white.get(), "measured_axis_x_px", cal.measured_axis_px[0]);
    write_attr(f, white.get(), "measured_axis_y_px", cal.measured_axis_px[1]);
    write_attr(f, white.get(), "measured_axis_sigma_px", cal.measured_axis_sigma_px);
    write_attr(f, white.get(), "black_level", cal.white_black_level);
    write_attr(f, white.get(), "calibration_frames", cal.calibration_frames);
    write_attr(f, white.get(), "white_frames", cal.white_frames);
    write_attr(f, white.get(), "dark_frames", cal.dark_frames);
  });
}

Calibration read_calibration_h5(const std::filesystem::path& path) {
  const File f{path};
  if (!std::filesystem::exists(path)) throw InputError(f.where("no such file"));
  if (H5Fis_hdf5(path.c_str()) <= 0) throw InputError(f.where("not an HDF5 file"));
  Handle file(H5Fopen(path.c_str(), H5F_ACC_RDONLY, H5P_DEFAULT), H5Fclose);
  if (!file.ok()) throw InputError(f.where("cannot open HDF5 file (corrupt?)"));
  const hid_t root = file.get();
  for (const char* group : {"lattice", "camera", "image"}) {
    if (H5Lexists(root, group, H5P_DEFAULT) <= 0) throw InputError(f.where(std::string("no group /") + group));
  }
  Handle lattice(H5Gopen2(root, "lattice", H5P_DEFAULT), H5Gclose);
  Handle camera(H5Gopen2(root, "camera", H5P_DEFAULT), H5Gclose);
  Handle image(H5Gopen2(root, "image", H5P_DEFAULT), H5Gclose);
  auto lat = [&](const char* name) { return read_attr(f, lattice.get(), "lattice", name); };
  auto cam = [&](const char* name) { return read_attr(f, camera.get(), "camera", name); };
  auto img = [&](const char* name) { return read_attr(f, image.get(), "image", name); };

  Calibration cal;
  cal.sensor.width_px = int(cam("sensor_width_px"));
  cal.sensor.height_px = int(cam("sensor_height_px"));
  cal.sensor.pixel_pitch_mm = cam("pixel_pitch_mm");
  cal.image_distance_mm = cam("image_distance_mm");
  cal.microlens_focal_length_mm = cam("microlens_focal_length_mm");
  if (read_attr_or(f, camera.get(), "camera", "optical_axis_given", 0) == 1) {
    cal.sensor.optical_axis_px = std::array<double, 2>{cam("optical_axis_x_px"), cam("optical_axis_y_px")};
  }
  cal.axis_measured =
      cal.sensor.optical_axis_px && read_attr_or(f, camera.get(), "camera", "optical_axis_measured", 0) == 1;
  if (cal.sensor.width_px <= 0 || cal.sensor.height_px <= 0 || !(cal.sensor.pixel_pitch_mm > 0) ||
      !(cal.image_distance_mm > 0) || !(cal.microlens_focal_length_mm > 0)) {
    throw InputError(f.where("/camera attributes are not a valid camera"));
  }
  const double pp = cal.sensor.pixel_pitch_mm;
  optics::Lattice& sl = cal.spot_lattice;
  sl.layout = lat("layout") == 1 ? optics::LensletLayout::hex : optics::LensletLayout::rect;
  sl.count_x = int(lat("count_x"));
  sl.count_y = int(lat("count_y"));
  if (sl.count_x <= 0 || sl.count_y <= 0) throw InputError(f.where("/lattice counts must be positive"));
  sl.pitch_x_mm = lat("spot_pitch_x_px") * pp;
  sl.pitch_y_mm = lat("spot_pitch_y_px") * pp;
  sl.rotation_rad = lat("rotation_rad");
  sl.offset_x_mm = lat("spot_offset_x_px") * pp;
  sl.offset_y_mm = lat("spot_offset_y_px") * pp;
  cal.rms_residual_px = lat("rms_residual_px");
  cal.max_residual_px = lat("max_residual_px");
  cal.spots_found = int(lat("spots_found"));
  cal.lenses_measured = int(lat("lenses_measured"));
  auto lat_or = [&](const char* name, double fallback) {
    return read_attr_or(f, lattice.get(), "lattice", name, fallback);
  };
  cal.lenses_lattice = int(lat_or("lenses_lattice", 0));
  cal.lenses_partial = int(lat_or("lenses_partial", 0));
  cal.lenses_rejected = int(lat_or("lenses_rejected", 0));
  cal.lenses_vignetted = int(lat_or("lenses_vignetted", 0));
  cal.source = lat_or("centres_from", 0) == 1 ? CentreSource::white : CentreSource::spots;
  cal.measurement_scatter_px = lat_or("measurement_scatter_px", 0);
  cal.array_scatter_px = lat_or("array_scatter_px", 0);
  cal.distortion_degree = int(lat_or("distortion_degree", 0));
  cal.nominal_spot_pitch_px = lat_or("nominal_spot_pitch_px", 0);
  cal.pitch_ratio = lat_or("pitch_ratio", 1);
  cal.image_stats.background = img("background");
  cal.image_stats.noise_sigma = img("noise_sigma");
  cal.image_stats.threshold = img("threshold");
  cal.image_stats.hot_pixels = int(img("hot_pixels"));

  // Lens counts the camera file gave when calibrated; files from before counts were optional
  // were made with counts equal to the array's.
  cal.camera_count_x = int(read_attr_or(f, camera.get(), "camera", "camera_count_x", sl.count_x));
  cal.camera_count_y = int(read_attr_or(f, camera.get(), "camera", "camera_count_y", sl.count_y));
  if (H5Lexists(root, "white", H5P_DEFAULT) > 0) {
    Handle white(H5Gopen2(root, "white", H5P_DEFAULT), H5Gclose);
    auto wh = [&](const char* name, double fallback) { return read_attr_or(f, white.get(), "white", name, fallback); };
    cal.fill = wh("fill", std::nan(""));
    cal.predicted_fill = wh("predicted_fill", 0);
    cal.measured_axis_px = {wh("measured_axis_x_px", std::nan("")), wh("measured_axis_y_px", std::nan(""))};
    cal.measured_axis_sigma_px = wh("measured_axis_sigma_px", std::nan(""));
    cal.white_black_level = wh("black_level", 0);
    cal.calibration_frames = int(wh("calibration_frames", 0));
    cal.white_frames = int(wh("white_frames", 0));
    cal.dark_frames = int(wh("dark_frames", 0));
  }

  const hsize_t nx = hsize_t(sl.count_x), ny = hsize_t(sl.count_y);
  cal.spots_px = pairs(read_set<double>(f, root, "spots_px", {ny, nx, 2}, H5T_NATIVE_DOUBLE));
  cal.residuals_px = pairs(read_set<double>(f, root, "residuals_px", {ny, nx, 2}, H5T_NATIVE_DOUBLE));
  for (const auto& q : cal.spots_px) {
    if (!std::isfinite(q[0]) || !std::isfinite(q[1])) throw InputError(f.where("/spots_px holds a non-finite value"));
  }
  const auto status = read_set<std::uint8_t>(f, root, "status", {ny, nx}, H5T_NATIVE_UINT8);
  cal.status.resize(status.size());
  for (std::size_t k = 0; k < status.size(); ++k) {
    if (status[k] > 4) throw InputError(f.where("/status holds an unknown value " + std::to_string(status[k])));
    cal.status[k] = LensStatus(status[k]);
  }
  const double nan = std::nan("");
  if (H5Lexists(root, "measured_px", H5P_DEFAULT) > 0) {
    cal.measured_px = pairs(read_set<double>(f, root, "measured_px", {ny, nx, 2}, H5T_NATIVE_DOUBLE));
  } else {  // older files: the spot of every measured lens is its measurement
    cal.measured_px.assign(cal.spots_px.size(), {nan, nan});
    for (std::size_t k = 0; k < cal.spots_px.size(); ++k) {
      if (cal.status[k] == LensStatus::measured) cal.measured_px[k] = cal.spots_px[k];
    }
  }
  cal.uncertainty_px = H5Lexists(root, "uncertainty_px", H5P_DEFAULT) > 0
                           ? read_set<double>(f, root, "uncertainty_px", {ny, nx}, H5T_NATIVE_DOUBLE)
                           : std::vector<double>(cal.spots_px.size(), nan);
  cal.white_correction.width = cal.sensor.width_px;
  cal.white_correction.height = cal.sensor.height_px;
  cal.white_correction.pixels = read_set<float, HugePageVector<float>>(
      f, root, "white_correction", {hsize_t(cal.sensor.height_px), hsize_t(cal.sensor.width_px)}, H5T_NATIVE_FLOAT);
  // A NaN, infinite or negative gain would spread through every reconstruction as NaN (no valid
  // vector, no error): refused here, where the file is named.
  for (std::size_t k = 0; k < cal.white_correction.pixels.size(); ++k) {
    const float w = cal.white_correction.pixels[k];
    if (!std::isfinite(w) || w < 0) {
      throw InputError(f.where("/white_correction holds " +
                               std::string(std::isfinite(w) ? "a negative" : "a non-finite") + " value at pixel (" +
                               std::to_string(k % std::size_t(cal.sensor.width_px)) + ", " +
                               std::to_string(k / std::size_t(cal.sensor.width_px)) + "): the file is damaged"));
    }
  }
  return cal;
}

LoadedCalibration load_calibration(const std::filesystem::path& path, const optics::CameraModel& camera) {
  Calibration cal = read_calibration_h5(path);
  const File f{path};
  const auto& s = camera.sensor();
  auto close = [](double a, double b) { return std::abs(a - b) <= 1e-9 * std::max(std::abs(a), std::abs(b)); };
  if (cal.sensor.width_px != s.width_px || cal.sensor.height_px != s.height_px ||
      !close(cal.sensor.pixel_pitch_mm, s.pixel_pitch_mm)) {
    throw InputError(f.where("made for a " + std::to_string(cal.sensor.width_px) + " x " +
                             std::to_string(cal.sensor.height_px) + " sensor, the camera file's is " +
                             std::to_string(s.width_px) + " x " + std::to_string(s.height_px)));
  }
  // A calibration belongs to the camera description it was made with: where the camera file gives
  // lens counts they must be the ones it gave then (older files: the array's own counts).
  const auto& ml = camera.microlens();
  const bool counts_differ =
      camera.counts_given() && (ml.count_x != cal.camera_count_x || ml.count_y != cal.camera_count_y) &&
      !(cal.camera_count_x == 0 && ml.count_x == cal.spot_lattice.count_x && ml.count_y == cal.spot_lattice.count_y);
  if (counts_differ || cal.spot_lattice.layout != ml.layout) {
    const std::string then =
        cal.camera_count_x == cal.spot_lattice.count_x && cal.camera_count_y == cal.spot_lattice.count_y ? ""
        : cal.camera_count_x > 0 ? " (its camera file gave " + std::to_string(cal.camera_count_x) + " x " +
                                       std::to_string(cal.camera_count_y) + ")"
                                 : " (its camera file gave no counts)";
    throw InputError(f.where(std::string("made for a ") + optics::to_string(cal.spot_lattice.layout) + " array of " +
                             std::to_string(cal.spot_lattice.count_x) + " x " +
                             std::to_string(cal.spot_lattice.count_y) + " lenses" + then + ", the camera file has " +
                             optics::to_string(ml.layout) + " " +
                             (camera.counts_given() ? std::to_string(ml.count_x) + " x " + std::to_string(ml.count_y)
                                                    : std::string("(no counts)")) +
                             ": calibrate again with this camera file"));
  }
  if (!close(cal.image_distance_mm, camera.image_distance_mm()) ||
      !close(cal.microlens_focal_length_mm, camera.microlens().focal_length_mm)) {
    throw InputError(f.where("made with s_i = " + std::to_string(cal.image_distance_mm) +
                             " mm, f_l = " + std::to_string(cal.microlens_focal_length_mm) +
                             " mm; the camera file gives s_i = " + std::to_string(camera.image_distance_mm()) +
                             " mm, f_l = " + std::to_string(camera.microlens().focal_length_mm) + " mm"));
  }
  // Lens centres in this camera's frame (its optical axis: the camera file's, else the one the
  // calibration measured, else the sensor centre), so that every spot stays where the calibration
  // measured it whatever the frame it was made in.
  std::optional<std::array<double, 2>> measured_axis;
  if (!camera.sensor().optical_axis_px && cal.axis_measured) measured_axis = cal.sensor.optical_axis_px;
  const std::array<double, 2> offset_px{optics::sensor_mm_to_column(cal.sensor, cal.spot_lattice.offset_x_mm),
                                        optics::sensor_mm_to_row(cal.sensor, cal.spot_lattice.offset_y_mm)};
  cal.sensor = camera.sensor();
  if (measured_axis) cal.sensor.optical_axis_px = measured_axis;
  cal.spot_lattice.offset_x_mm = optics::column_to_sensor_mm(cal.sensor, offset_px[0]);
  cal.spot_lattice.offset_y_mm = optics::row_to_sensor_mm(cal.sensor, offset_px[1]);
  return {cal.microlens_array(), std::move(cal.white_correction), measured_axis};
}

LoadedCalibration loaded_calibration(Calibration cal) {
  std::optional<std::array<double, 2>> measured_axis;
  if (cal.axis_measured) measured_axis = cal.sensor.optical_axis_px;
  return {cal.microlens_array(), std::move(cal.white_correction), measured_axis};
}

optics::CameraModel camera_in_frame(const optics::CameraModel& camera, const LoadedCalibration& calibration) {
  if (!calibration.measured_optical_axis_px || camera.sensor().optical_axis_px) return camera;
  return camera.with_optical_axis(*calibration.measured_optical_axis_px);
}

}  // namespace plenopiv::calib
