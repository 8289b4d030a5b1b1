// core/process's run config: the depth guard's grid, MART's knobs, refusal of bad values, and that
// process_pair hands back the box the user asked for (guard slices reconstructed, then dropped).
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include "core/base/errors.hpp"
#include "core/base/yaml_access.hpp"
#include "core/calib/nominal_calibration.hpp"
#include "core/optics/camera_file.hpp"
#include "core/process/pair_processor.hpp"
#include "core/process/process.hpp"
#include "core/recon/mart.hpp"
#include "core/recon/weights.hpp"
#include "core/sim/render.hpp"

namespace plenopiv::process {
namespace {

ProcessSettings parse(const std::string& text) {
  return process_settings_from(YamlMap(load_yaml_text(text, "run.yaml"), "run.yaml"));
}

const std::string kVolume = "dt_s: 0.001\nvolume: {x_mm: [-1, 1], y_mm: [-1, 1], z_mm: [2, 4], voxel_mm: 0.125";
const std::string kPasses = "correlation: {passes: [{window: 8, overlap_percent: 50}]}\n";

// The run config `text` is refused with an InputError that names `key`.
void expect_refused_naming(const std::string& text, const std::string& key) {
  try {
    parse(text);
    ADD_FAILURE() << "accepted: " << text;
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find(key), std::string::npos) << e.what();
  }
}

TEST(ProcessSettings, TheDepthGuardAddsWholeSlicesAtBothDepthEnds) {
  const ProcessSettings s = parse(kVolume + ", depth_guard_mm: 0.3}\n" + kPasses);
  EXPECT_EQ(s.grid.shape[2], 16);
  EXPECT_EQ(s.guard_slices(), 3);  // 0.3 mm in 0.125 mm slices, rounded up
  const Grid3 r = s.reconstruction_grid();
  EXPECT_EQ(r.shape[0], s.grid.shape[0]);
  EXPECT_EQ(r.shape[1], s.grid.shape[1]);
  EXPECT_EQ(r.shape[2], 16 + 6);
  EXPECT_DOUBLE_EQ(r.origin_mm[2], s.grid.origin_mm[2] - 3 * 0.125);
  EXPECT_DOUBLE_EQ(r.coordinate_mm(2, 3), s.grid.coordinate_mm(2, 0));

  EXPECT_DOUBLE_EQ(parse(kVolume + "}\n" + kPasses).depth_guard_mm, 1.0);  // the default
  EXPECT_EQ(parse(kVolume + ", depth_guard_mm: 0}\n" + kPasses).reconstruction_grid(),
            parse(kVolume + "}\n" + kPasses).grid);
}

// process-paper.yaml is run-paper.yaml's full tier on voxels half a lens pitch across: the same box,
// the same passes, overlaps, margins and whitened peak in mm, the same floor, filters and searches,
// more iterations for four times the voxels per depth slice, and w through the same depth response.
TEST(ProcessSettings, ThePaperAccuracyConfigIsRunPapersBoxAndCorrelationInMmOnHalfPitchVoxels) {
  const std::string dir = std::string(PLENOPIV_SOURCE_DIR) + "/systemd/config/";
  const auto load = [&](const std::string& name) {
    return process_spec_from(YamlMap(processing_part(load_yaml_file(dir + name)), name)).full;
  };
  const ProcessSettings fine = load("process-paper.yaml"), paper = load("run-paper.yaml");
  EXPECT_EQ(fine.grid.shape, (std::array<int, 3>{600, 400, 100}));
  EXPECT_EQ(fine.grid.spacing_mm, (std::array<double, 3>{0.0625, 0.0625, 0.25}));
  for (int a = 0; a < 3; ++a) {
    // The same faces: node 0's centre half a voxel inside, the same extent.
    EXPECT_DOUBLE_EQ(fine.grid.origin_mm[a] - 0.5 * fine.grid.spacing_mm[a],
                     paper.grid.origin_mm[a] - 0.5 * paper.grid.spacing_mm[a]);
    EXPECT_DOUBLE_EQ(fine.grid.shape[a] * fine.grid.spacing_mm[a], paper.grid.shape[a] * paper.grid.spacing_mm[a]);
  }
  EXPECT_GT(fine.mart.iterations, paper.mart.iterations);
  EXPECT_GT(fine.depth_response_ppm, 0.0);                       // its minutes of set-up buy w and a calibrated sigma
  EXPECT_EQ(fine.depth_response_ppm, paper.depth_response_ppm);  // the same seeding
  EXPECT_EQ(fine.mart.accelerate, paper.mart.accelerate);
  EXPECT_EQ(fine.mart.mu, paper.mart.mu);
  EXPECT_EQ(fine.mart.prune_threshold, paper.mart.prune_threshold);
  EXPECT_EQ(fine.mart.prune_scope, paper.mart.prune_scope);
  const piv::CorrelationSettings &f = fine.correlation, &p = paper.correlation;
  ASSERT_EQ(f.passes.size(), p.passes.size());
  for (std::size_t k = 0; k < f.passes.size(); ++k) {
    for (int a = 0; a < 3; ++a)
      EXPECT_DOUBLE_EQ(f.passes[k].window[a] * fine.grid.spacing_mm[a],
                       p.passes[k].window[a] * paper.grid.spacing_mm[a])
          << "pass " << k + 1 << ", axis " << a;
    EXPECT_EQ(f.passes[k].overlap_percent, p.passes[k].overlap_percent);
    EXPECT_EQ(f.passes[k].depth_margin, p.passes[k].depth_margin);  // depth voxels alike
  }
  for (int a = 0; a < 3; ++a)
    EXPECT_DOUBLE_EQ(f.whitened_peak_sigma_voxel[a] * fine.grid.spacing_mm[a],
                     p.whitened_peak_sigma_voxel[a] * paper.grid.spacing_mm[a]);
  EXPECT_EQ(f.intensity_threshold_of_mean, p.intensity_threshold_of_mean);
  EXPECT_EQ(f.depth_prefilter, p.depth_prefilter);
  EXPECT_EQ(f.final_smoothing, p.final_smoothing);
  EXPECT_EQ(f.spectral_whitening, p.spectral_whitening);
  EXPECT_EQ(f.early_interpolation, p.early_interpolation);
  EXPECT_EQ(f.uncertainty_stride, p.uncertainty_stride);
  EXPECT_EQ(f.final_peak_search, p.final_peak_search);
}

TEST(ProcessSettings, ABadDepthGuardIsNamed) {
  for (const std::string bad : {"-0.5", "1000", "many"}) {
    expect_refused_naming(kVolume + ", depth_guard_mm: " + bad + "}\n" + kPasses, "depth_guard_mm");
  }
}

// A whole number outside its range is refused before it narrows to int: 4294967297 would be 1.
TEST(ProcessSettings, IterationsOutOfRangeAreNamedAndNeverWrap) {
  EXPECT_EQ(parse(kVolume + "}\nreconstruction: {iterations: 10000}\n" + kPasses).mart.iterations, 10000);
  for (const std::string bad : {"0", "10001", "4294967297", "2.5"}) {
    expect_refused_naming(kVolume + "}\nreconstruction: {iterations: " + bad + "}\n" + kPasses, "iterations");
  }
}

TEST(ProcessSettings, AngularSamplingReachesTheOperator) {
  EXPECT_DOUBLE_EQ(parse(kVolume + "}\n" + kPasses).angular_sampling, 1.0);  // the default
  const ProcessSettings s = parse(kVolume + "}\nreconstruction: {angular_sampling: 2}\n" + kPasses);
  EXPECT_DOUBLE_EQ(s.angular_sampling, 2.0);
  const auto camera = optics::load_camera_file(std::string(PLENOPIV_SOURCE_DIR) + "/systemd/config/camera-small.yaml");
  const auto lenses = optics::MicrolensArray::from_lattice(optics::Lattice::nominal(camera));
  const PairOperator op(camera, lenses, calib::geometric_white_image(camera, lenses), s);
  EXPECT_EQ(op.weights().grid(), s.reconstruction_grid());
  EXPECT_DOUBLE_EQ(op.weights().geometry().angular_sampling, 2.0);
  for (const std::string bad : {"0", "-1", "20", "fine"}) {
    expect_refused_naming(kVolume + "}\nreconstruction: {angular_sampling: " + bad + "}\n" + kPasses,
                          "angular_sampling");
  }
}

TEST(ProcessSettings, AccelerationReachesMart) {
  EXPECT_FALSE(parse(kVolume + "}\n" + kPasses).mart.accelerate);  // the paper's iteration by default
  EXPECT_TRUE(parse(kVolume + "}\nreconstruction: {acceleration: nesterov}\n" + kPasses).mart.accelerate);
  EXPECT_FALSE(parse(kVolume + "}\nreconstruction: {acceleration: none}\n" + kPasses).mart.accelerate);
  for (const std::string bad : {"fista", "yes", "1"}) {
    expect_refused_naming(kVolume + "}\nreconstruction: {acceleration: " + bad + "}\n" + kPasses, "acceleration");
  }
}

TEST(ProcessSettings, SensorBlurReachesMart) {
  EXPECT_EQ(parse(kVolume + "}\n" + kPasses).mart.sensor_blur_sigma_mm, 0.0);  // sec 5.2's weights alone
  EXPECT_DOUBLE_EQ(
      parse(kVolume + "}\nreconstruction: {sensor_blur_sigma_mm: 0.0052}\n" + kPasses).mart.sensor_blur_sigma_mm,
      0.0052);
  for (const std::string bad : {"-0.001", "0.5", "wide"}) {
    expect_refused_naming(kVolume + "}\nreconstruction: {sensor_blur_sigma_mm: " + bad + "}\n" + kPasses,
                          "sensor_blur_sigma_mm");
  }
}

TEST(ProcessSettings, PruningReachesMart) {
  const ProcessSettings defaults = parse(kVolume + "}\n" + kPasses);
  EXPECT_TRUE(defaults.mart.prune);  // exact zeros only: the volume of no pruning
  EXPECT_EQ(defaults.mart.prune_threshold, 0.0);
  EXPECT_EQ(defaults.mart.prune_scope, recon::PruneScope::volume);
  const ProcessSettings s = parse(kVolume + "}\nreconstruction: {prune: false, prune_threshold: 0.01}\n" + kPasses);
  EXPECT_FALSE(s.mart.prune);
  EXPECT_DOUBLE_EQ(s.mart.prune_threshold, 0.01);
  EXPECT_EQ(parse(kVolume + "}\nreconstruction: {prune_scope: slice}\n" + kPasses).mart.prune_scope,
            recon::PruneScope::slice);
  expect_refused_naming(kVolume + "}\nreconstruction: {prune_scope: lens}\n" + kPasses, "prune_scope");
  EXPECT_EQ(defaults.mart.start, recon::MartStart::mlos);
  EXPECT_EQ(parse(kVolume + "}\nreconstruction: {start: ones}\n" + kPasses).mart.start, recon::MartStart::ones);
  expect_refused_naming(kVolume + "}\nreconstruction: {start: zeros}\n" + kPasses, "start");
  for (const std::string bad : {"-0.001", "1", "faint"}) {
    expect_refused_naming(kVolume + "}\nreconstruction: {prune_threshold: " + bad + "}\n" + kPasses, "prune_threshold");
  }
  expect_refused_naming(kVolume + "}\nreconstruction: {prune: sometimes}\n" + kPasses, "prune");
  EXPECT_EQ(defaults.mart.prune_depth_reach, 0);
  EXPECT_EQ(parse(kVolume + "}\nreconstruction: {prune_depth_reach: 2}\n" + kPasses).mart.prune_depth_reach, 2);
  for (const std::string bad : {"-1", "33", "near"}) {
    expect_refused_naming(kVolume + "}\nreconstruction: {prune_depth_reach: " + bad + "}\n" + kPasses,
                          "prune_depth_reach");
  }
  EXPECT_EQ(defaults.mart.prune_local_threshold, 0.0);
  EXPECT_EQ(parse(kVolume + "}\nreconstruction: {prune_local_threshold: 0.05}\n" + kPasses).mart.prune_local_threshold,
            0.05);
  for (const std::string bad : {"-0.001", "1", "near"}) {
    expect_refused_naming(kVolume + "}\nreconstruction: {prune_local_threshold: " + bad + "}\n" + kPasses,
                          "prune_local_threshold");
  }
  EXPECT_EQ(defaults.mart.mlos_power, 1.0);
  EXPECT_EQ(parse(kVolume + "}\nreconstruction: {mlos_power: 3}\n" + kPasses).mart.mlos_power, 3.0);
  for (const std::string bad : {"0.5", "9", "sharp"}) {
    expect_refused_naming(kVolume + "}\nreconstruction: {mlos_power: " + bad + "}\n" + kPasses, "mlos_power");
  }
}

// Two particles at depths z and z + 0.5 mm through the small camera, as the camera records them.
ImageF two_particle_frame(const optics::CameraModel& camera, const optics::MicrolensArray& lenses, double z) {
  sim::RenderOptions ro;
  ro.rays_per_particle = 2000;
  const std::vector<sim::Point3> particles{{0.1, -0.2, z}, {-0.4, 0.3, z + 0.5}};
  const auto r = sim::render(camera, lenses, particles, ro, 3);
  ImageF f(r.image.width, r.image.height);
  for (std::size_t i = 0; i < f.size(); ++i) f.pixels[i] = r.image.pixels[i];
  return f;
}

TEST(ProcessSettings, ProcessPairReturnsTheRequestedBoxAndRefusesAnUnguardedOperator) {
  const auto camera = optics::load_camera_file(std::string(PLENOPIV_SOURCE_DIR) + "/systemd/config/camera-small.yaml");
  const auto lenses = optics::MicrolensArray::from_lattice(optics::Lattice::nominal(camera));
  ProcessSettings s = parse(kVolume + ", depth_guard_mm: 0.25}\n" + kPasses);
  const ImageF a = two_particle_frame(camera, lenses, 3.0), b = two_particle_frame(camera, lenses, 3.1);
  const recon::WeightingOperator guarded(camera, lenses, s.reconstruction_grid(),
                                         calib::geometric_white_image(camera, lenses));
  const PairResult r = process_pair(guarded, a, b, s);
  EXPECT_EQ(r.volume_a.grid, s.grid);
  EXPECT_EQ(r.volume_b.grid, s.grid);
  double light = 0;
  for (float v : r.volume_a.data) light += v;
  EXPECT_GT(light, 0.0);  // the particles' slices are inside the returned box
  // Exactly the inner slices of the guarded reconstruction (deterministic kernels: bit for bit).
  const Volume full = recon::reconstruct(guarded, a, s.mart).volume;
  const std::size_t slice = std::size_t(s.grid.shape[0]) * std::size_t(s.grid.shape[1]);
  const HugePageVector<float> inner(
      full.data.begin() + std::ptrdiff_t(std::size_t(s.guard_slices()) * slice),
      full.data.begin() + std::ptrdiff_t(std::size_t(s.guard_slices()) * slice + s.grid.count()));
  EXPECT_EQ(r.volume_a.data, inner);

  const recon::WeightingOperator unguarded(camera, lenses, s.grid, calib::geometric_white_image(camera, lenses));
  EXPECT_THROW(process_pair(unguarded, a, b, s), InputError);
}

// A caller's kept MART and correlation workspaces (the daemon's, pair after pair) change no bit: a
// pair processed after another in the same workspaces gives the volumes and vectors of one
// processed alone, and frame B (reconstructed in A's buffers) the volume of B reconstructed first.
TEST(ProcessSettings, AKeptWorkspaceGivesTheSameVolumesAndVectors) {
  const auto camera = optics::load_camera_file(std::string(PLENOPIV_SOURCE_DIR) + "/systemd/config/camera-small.yaml");
  const auto lenses = optics::MicrolensArray::from_lattice(optics::Lattice::nominal(camera));
  const ProcessSettings s = parse(kVolume + ", depth_guard_mm: 0.25}\n" + kPasses);
  const ImageF a = two_particle_frame(camera, lenses, 3.0), b = two_particle_frame(camera, lenses, 3.1);
  const PairOperator op(camera, lenses, calib::geometric_white_image(camera, lenses), s);
  const PairResult alone = process_pair(op, a, b, s);
  recon::MartWorkspace workspace;
  piv::CorrelationWorkspace correlation;
  const PairResult reversed = process_pair(op, b, a, s, {}, &workspace, &correlation);
  const PairResult kept = process_pair(op, a, b, s, {}, &workspace, &correlation);
  EXPECT_EQ(reversed.volume_a.data, alone.volume_b.data);
  EXPECT_EQ(kept.volume_a.data, alone.volume_a.data);
  EXPECT_EQ(kept.volume_b.data, alone.volume_b.data);
  EXPECT_EQ(kept.correlation.field.dx_mm, alone.correlation.field.dx_mm);
  EXPECT_EQ(kept.correlation.field.dy_mm, alone.correlation.field.dy_mm);
  EXPECT_EQ(kept.correlation.field.dz_mm, alone.correlation.field.dz_mm);
  EXPECT_EQ(kept.correlation.field.valid, alone.correlation.field.valid);
  EXPECT_NE(alone.volume_a.data, alone.volume_b.data);  // two different frames
  EXPECT_GT(workspace.bytes(), 0u);                     // the pairs ran in it
  EXPECT_GT(correlation.bytes(), 0u);
}

// Workspaces reserved for the operator's largest reconstruction (every voxel of the box active) and
// its correlation (plenopivd reserves its lanes' buffers while a run is Armed) change no bit, and
// no pair grows them: neither a particle pair nor frames lit on every pixel (the most voxels MART
// can keep). (The list of active voxels is the selection's own, made per frame: it may shrink.)
// PairProcessor's pool reserved twice, with a pair between, holds the same bytes. MART prunes
// with a depth reach and a neighbourhood cut, so their buffers are reserved too.
TEST(ProcessSettings, AReservedWorkspaceChangesNoBitAndNoPairGrowsIt) {
  const auto camera = optics::load_camera_file(std::string(PLENOPIV_SOURCE_DIR) + "/systemd/config/camera-small.yaml");
  const auto lenses = optics::MicrolensArray::from_lattice(optics::Lattice::nominal(camera));
  const ProcessSettings s = parse(kVolume + ", depth_guard_mm: 0.25}\n" +
                                  "reconstruction: {prune_threshold: 0.05, prune_scope: slice, prune_depth_reach: 2, "
                                  "prune_local_threshold: 0.05}\n" +
                                  kPasses);
  const ImageF a = two_particle_frame(camera, lenses, 3.0), b = two_particle_frame(camera, lenses, 3.1);
  const PairOperator op(camera, lenses, calib::geometric_white_image(camera, lenses), s);
  const PairResult alone = process_pair(op, a, b, s);

  recon::MartWorkspace workspace;
  piv::CorrelationWorkspace correlation;
  workspace.reserve(op.weights());
  correlation.reserve(op.weights().grid().count());
  const std::size_t mart_bytes = workspace.bytes(), correlation_bytes = correlation.bytes();
  EXPECT_GE(mart_bytes, 6 * op.weights().grid().count() * sizeof(float));  // the per-voxel arrays
  EXPECT_EQ(correlation_bytes, 4 * op.weights().grid().count() * sizeof(float));
  const PairResult kept = process_pair(op, a, b, s, {}, &workspace, &correlation);
  EXPECT_EQ(kept.volume_a.data, alone.volume_a.data);
  EXPECT_EQ(kept.volume_b.data, alone.volume_b.data);
  EXPECT_EQ(kept.correlation.field.dx_mm, alone.correlation.field.dx_mm);
  EXPECT_EQ(kept.correlation.field.dz_mm, alone.correlation.field.dz_mm);
  EXPECT_EQ(kept.correlation.flags, alone.correlation.flags);
  EXPECT_LE(workspace.bytes(), mart_bytes);
  EXPECT_EQ(correlation.bytes(), correlation_bytes);

  ImageF lit(a.width, a.height);
  for (float& v : lit.pixels) v = 1000.f;
  const recon::MartResult all = recon::reconstruct(op.weights(), lit, s.mart, workspace);
  EXPECT_EQ(all.skipped.voxels_dark, 0u);  // every voxel a pixel sees is active
  EXPECT_GT(all.skipped.voxels_active, all.skipped.voxels / 2);
  EXPECT_LE(workspace.bytes(), mart_bytes);

  const calib::LoadedCalibration calibration = calib::nominal_calibration(camera);
  const PairProcessor processor(camera, calibration, s);
  const std::size_t pool_bytes = processor.reserve_workspaces(2);
  EXPECT_GE(pool_bytes, 2 * (mart_bytes + correlation_bytes) * 9 / 10);
  ImageU16 raw_a(camera.sensor().width_px, camera.sensor().height_px), raw_b = raw_a;
  for (std::size_t i = 0; i < raw_a.pixels.size(); ++i) {
    raw_a.pixels[i] = std::uint16_t(std::min(a.pixels[i], 65535.f));
    raw_b.pixels[i] = std::uint16_t(std::min(b.pixels[i], 65535.f));
  }
  processor.process(raw_a, raw_b);
  EXPECT_EQ(processor.reserve_workspaces(2), pool_bytes);
}

// Cancelling from the progress callback (plenopiv::Cancelled, as the daemon's stop does) abandons
// the pair during frame B or the correlation and leaves the workspace usable.
TEST(ProcessSettings, CancellingFromProgressAbandonsThePairAndFreesTheWorkspace) {
  const auto camera = optics::load_camera_file(std::string(PLENOPIV_SOURCE_DIR) + "/systemd/config/camera-small.yaml");
  const auto lenses = optics::MicrolensArray::from_lattice(optics::Lattice::nominal(camera));
  ProcessSettings s =
      parse(kVolume + ", depth_guard_mm: 0.25}\n" +
            "correlation: {passes: [{window: 8, overlap_percent: 50}, {window: 8, overlap_percent: 50}]}\n");
  const ImageF a = two_particle_frame(camera, lenses, 3.0), b = two_particle_frame(camera, lenses, 3.1);
  const PairOperator op(camera, lenses, calib::geometric_white_image(camera, lenses), s);
  recon::MartWorkspace workspace;
  // During frame B's reconstruction, and after the correlation's first pass.
  for (const std::string when : {"reconstruct B", "correlate"}) {
    std::string last;
    EXPECT_THROW(process_pair(
                     op, a, b, s,
                     [&](const std::string& stage, double) {
                       last = stage;
                       if (stage == when) throw plenopiv::Cancelled("run stopping");
                     },
                     &workspace),
                 plenopiv::Cancelled)
        << when;
    EXPECT_EQ(last, when);
  }
  const PairResult done = process_pair(op, a, b, s, {}, &workspace);
  EXPECT_EQ(done.volume_a.data, process_pair(op, a, b, s).volume_a.data);
}

// The progress fraction rises to 1 and gives each correlation pass its share of the time: a
// 8³@75 % pass has 8x the windows of an 8³@50 % pass, so the first of the two ends well before
// the correlation's halfway point.
TEST(ProcessSettings, ProgressGivesADenserPassItsShare) {
  const auto camera = optics::load_camera_file(std::string(PLENOPIV_SOURCE_DIR) + "/systemd/config/camera-small.yaml");
  const auto lenses = optics::MicrolensArray::from_lattice(optics::Lattice::nominal(camera));
  ProcessSettings s =
      parse(kVolume + ", depth_guard_mm: 0.25}\n" +
            "correlation: {passes: [{window: 8, overlap_percent: 50}, {window: 8, overlap_percent: 75}]}\n");
  const ImageF a = two_particle_frame(camera, lenses, 3.0), b = two_particle_frame(camera, lenses, 3.1);
  const PairOperator op(camera, lenses, calib::geometric_white_image(camera, lenses), s);
  std::vector<std::pair<std::string, double>> seen;
  process_pair(op, a, b, s, [&](const std::string& stage, double f) { seen.emplace_back(stage, f); });
  ASSERT_FALSE(seen.empty());
  for (std::size_t i = 1; i < seen.size(); ++i) EXPECT_GE(seen[i].second, seen[i - 1].second) << seen[i].first;
  EXPECT_EQ(seen.back(), std::make_pair(std::string("done"), 1.0));
  std::vector<double> correlate;
  for (const auto& [stage, f] : seen)
    if (stage == "correlate") correlate.push_back(f);
  ASSERT_EQ(correlate.size(), 2u);
  // 2 units against 9 (process.cpp's correlation_progress): 0.8 + 0.2 * 2 / 11.
  EXPECT_NEAR(correlate[0], 0.8 + 0.2 * 2 / 11, 1e-9);
  EXPECT_DOUBLE_EQ(correlate[1], 1.0);
}

}  // namespace
}  // namespace plenopiv::process
