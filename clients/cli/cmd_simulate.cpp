// `plenopiv simulate`: ray-traced plenoptic images of particle lists, calibration and white
// targets, and frame pairs of a seeded particle field moved by a flow (core/sim).
#include <charconv>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <memory>
#include <sstream>

#include "clients/cli/commands.hpp"
#include "clients/cli/options.hpp"
#include "clients/cli/progress.hpp"
#include "core/base/errors.hpp"
#include "core/base/yaml_access.hpp"
#include "core/io/atomic_file.hpp"
#include "core/io/tiff.hpp"
#include "core/optics/camera_file.hpp"
#include "core/sim/flows.hpp"
#include "core/sim/particle_file.hpp"
#include "core/sim/render.hpp"

namespace plenopiv::client {
namespace {

// Options every simulate command shares: the camera, the true lens array, the sensor, the seed.
struct CommonOptions {
  std::string camera;
  std::string output;
  long long seed = 1;
  double diffraction_um = 5.2;
  double array_rotation_rad = 0;
  std::vector<double> array_offset_mm{0, 0};
  double lens_jitter_mm = 0;
  sim::SensorModel sensor;
  int threads = 0;
};

void add_common(CLI::App* cmd, CommonOptions& o, const std::string& output_help) {
  add_camera_option(cmd, o.camera)->required();
  cmd->add_option("-o,--output", o.output, output_help)->required();
  add_threads_option(cmd, o.threads);
  cmd->add_option("--seed", o.seed, "random seed (same seed, same image)")->capture_default_str();
  cmd->add_option("--diffraction-um", o.diffraction_um,
                  "diffraction jitter sigma at the microlens and sensor planes, um (0: off)")
      ->capture_default_str();
  cmd->add_option("--array-rotation-rad", o.array_rotation_rad, "rotation of the true lens array")
      ->capture_default_str();
  cmd->add_option("--array-offset-mm", o.array_offset_mm, "offset x,y of the true lens array, mm")
      ->delimiter(',')
      ->expected(2);
  cmd->add_option("--lens-jitter-mm", o.lens_jitter_mm, "per-lens Gaussian position jitter, mm")->capture_default_str();
  cmd->add_option("--electrons-per-ray", o.sensor.electrons_per_ray, "sensor: electrons per landed ray")
      ->capture_default_str();
  cmd->add_flag("--shot-noise", o.sensor.shot_noise, "sensor: Poisson shot noise");
  cmd->add_option("--read-noise-e", o.sensor.read_noise_electrons, "sensor: read noise sigma, electrons")
      ->capture_default_str();
  cmd->add_option("--dark-offset-dn", o.sensor.dark_offset_dn, "sensor: dark offset, counts")->capture_default_str();
  cmd->add_option("--gain", o.sensor.gain_dn_per_electron, "sensor: counts per electron")->capture_default_str();
  cmd->add_option("--bit-depth", o.sensor.bit_depth, "sensor: bits (saturates at 2^bits - 1)")->capture_default_str();
}

double diffraction_mm(const CommonOptions& o) {
  if (!std::isfinite(o.diffraction_um) || o.diffraction_um < 0) {
    throw InputError("--diffraction-um: must be >= 0, got " + std::to_string(o.diffraction_um));
  }
  return o.diffraction_um * 1e-3;
}

std::uint64_t seed_of(const CommonOptions& o) {
  if (o.seed < 0) throw InputError("--seed: must be >= 0, got " + std::to_string(o.seed));
  return std::uint64_t(o.seed);
}

optics::MicrolensArray true_array(const optics::CameraModel& camera, const CommonOptions& o) {
  optics::Lattice lattice = optics::Lattice::nominal(camera);
  lattice.rotation_rad = o.array_rotation_rad;
  lattice.offset_x_mm = o.array_offset_mm[0];
  lattice.offset_y_mm = o.array_offset_mm[1];
  if (!std::isfinite(o.lens_jitter_mm) || o.lens_jitter_mm < 0) {
    throw InputError("--lens-jitter-mm: must be >= 0, got " + std::to_string(o.lens_jitter_mm));
  }
  return o.lens_jitter_mm > 0 ? sim::jittered_array(lattice, o.lens_jitter_mm, seed_of(o) ^ 0xa11a7ULL)
                              : optics::MicrolensArray::from_lattice(lattice);
}

// How much the particles' light differs (sim::RenderOptions::brightness_spread), for the commands
// that render particles.
void add_brightness_option(CLI::App* cmd, double& spread) {
  cmd->add_option("--brightness-spread", spread,
                  "each particle's light a log-normal factor of mean 1 whose log has this spread, as a real "
                  "seeding's sizes differ (0 to 3; 0: every particle alike)")
      ->capture_default_str();
}

std::size_t ray_count(long long rays, const char* option) {
  if (rays <= 0) throw InputError(std::string(option) + ": must be a positive ray count, got " + std::to_string(rays));
  return std::size_t(rays);
}

void report(const std::string& what, const sim::RayCounts& c) {
  std::cerr << what << ": " << c.emitted << " rays, " << c.landed << " landed, " << c.outside_sensor
            << " off the sensor, " << c.missed_array << " beside the lens array, " << c.outside_aperture
            << " stopped by the aperture\n";
}

sim::RenderResult render_with_progress(const optics::CameraModel& camera, const optics::MicrolensArray& array,
                                       const std::vector<sim::Point3>& particles, sim::RenderOptions options,
                                       std::uint64_t seed, const std::string& label) {
  auto progress =
      std::make_shared<Progress>(label, "Mrays", double(particles.size()) * options.rays_per_particle * 1e-6);
  options.progress = [progress](double f) { progress->update(f); };
  return sim::render(camera, array, particles, options, seed);
}

// The directory of an output file must exist: say so rather than fail in the TIFF writer.
void check_output_folder(const std::filesystem::path& file) {
  const auto dir = file.parent_path();
  if (!dir.empty() && !std::filesystem::is_directory(dir)) {
    throw InputError(file.string() + ": folder " + dir.string() + " does not exist");
  }
}

std::string num(double v) {
  char buf[40];
  const auto end = std::to_chars(buf, buf + sizeof buf, v).ptr;  // shortest exact form
  return std::string(buf, end);
}

void write_text(const std::filesystem::path& path, const std::string& text) {
  io::write_atomically(path, [&](const std::filesystem::path& tmp) {
    std::FILE* f = std::fopen(tmp.c_str(), "w");
    if (!f) throw InputError(path.string() + ": cannot write");
    const bool ok = std::fputs(text.c_str(), f) >= 0;
    if (std::fclose(f) != 0 || !ok) throw InputError(path.string() + ": write error");
  });
}

// The simulator's true array, for calibration tests: each lens centre (microlens plane, mm) and
// where its spot falls (optics::lens_centre_to_spot_mm, in pixels).
std::string lens_truth_csv(const optics::CameraModel& camera, const optics::MicrolensArray& array) {
  std::string text = "i,j,centre_x_mm,centre_y_mm,spot_column,spot_row\n";
  const double s_i = camera.image_distance_mm(), f_l = camera.microlens().focal_length_mm;
  for (int j = 0; j < array.lattice.count_y; ++j) {
    for (int i = 0; i < array.lattice.count_x; ++i) {
      const auto& c = array.centre(i, j);
      text += std::to_string(i) + "," + std::to_string(j) + "," + num(c[0]) + "," + num(c[1]) + "," +
              num(optics::sensor_mm_to_column(camera.sensor(), optics::lens_centre_to_spot_mm(c[0], s_i, f_l))) + "," +
              num(optics::sensor_mm_to_row(camera.sensor(), optics::lens_centre_to_spot_mm(c[1], s_i, f_l))) + "\n";
    }
  }
  return text;
}

void add_particles_command(CLI::App& simulate) {
  auto* cmd = simulate.add_subcommand("particles", "render a particle list (CSV x,y,z in mm) to a 16-bit TIFF");
  auto o = std::make_shared<CommonOptions>();
  auto csv = std::make_shared<std::string>();
  auto rays = std::make_shared<long long>(10000);
  auto spread = std::make_shared<double>(0.0);
  add_common(cmd, *o, "output image (16-bit TIFF)");
  cmd->add_option("--particles", *csv, "particle list: CSV, x,y,z in mm, header allowed")->required();
  cmd->add_option("--rays", *rays, "rays per particle")->capture_default_str();
  add_brightness_option(cmd, *spread);
  cmd->callback([o, csv, rays, spread] {
    const auto limit = thread_limit(o->threads);
    const optics::CameraModel camera = optics::load_camera_file(o->camera);
    sim::RenderOptions options;
    options.rays_per_particle = ray_count(*rays, "--rays");
    options.diffraction_sigma_mm = diffraction_mm(*o);
    options.sensor = o->sensor;
    options.brightness_spread = *spread;
    options.brightness_seed = seed_of(*o);
    check_output_folder(o->output);
    const auto particles = sim::read_particles_csv(*csv);
    const auto result =
        render_with_progress(camera, true_array(camera, *o), particles, options, seed_of(*o), "rendering");
    io::write_tiff(o->output, result.image);
    report(o->output, result.counts);
  });
}

void add_target_command(CLI::App& simulate, const std::string& name, bool calibration) {
  auto* cmd = simulate.add_subcommand(
      name, calibration ? "calibration image: stopped-down aperture, white target at the focal plane"
                        : "white image: open aperture, white target at the focal plane");
  auto o = std::make_shared<CommonOptions>();
  auto t = std::make_shared<sim::TargetOptions>(calibration ? sim::calibration_target() : sim::white_target());
  auto rays = std::make_shared<long long>(static_cast<long long>(t->rays_per_lens));
  auto truth = std::make_shared<std::string>();
  add_common(cmd, *o, "output image (16-bit TIFF)");
  cmd->add_option("--truth", *truth, "also write the true lens centres (CSV: i, j, centre x/y mm, spot column/row px)");
  cmd->add_option("--f-number", t->f_number,
                  calibration ? "main-lens f-number while calibrating" : "main-lens f-number (0: the camera's)")
      ->capture_default_str();
  cmd->add_option("--rays-per-lens", *rays, "rays per microlens area")->capture_default_str();
  cmd->callback([o, t, rays, truth, name] {
    const auto limit = thread_limit(o->threads);
    const optics::CameraModel camera = optics::load_camera_file(o->camera);
    sim::TargetOptions options = *t;
    options.rays_per_lens = ray_count(*rays, "--rays-per-lens");
    options.diffraction_sigma_mm = diffraction_mm(*o);
    options.sensor = o->sensor;
    check_output_folder(o->output);
    auto progress =
        std::make_shared<Progress>(name, "Mrays", double(camera.lens_count()) * options.rays_per_lens * 1e-6);
    options.progress = [progress](double f) { progress->update(f); };
    const optics::MicrolensArray array = true_array(camera, *o);
    if (!truth->empty()) check_output_folder(*truth);
    const auto result = sim::render_target(camera, array, options, seed_of(*o));
    io::write_tiff(o->output, result.image);
    if (!truth->empty()) write_text(*truth, lens_truth_csv(camera, array));
    report(o->output, result.counts);
  });
}

void add_pair_command(CLI::App& simulate) {
  auto* cmd =
      simulate.add_subcommand("pair", "frame pair A/B: a seeded particle field and the same field moved by a flow");
  auto o = std::make_shared<CommonOptions>();
  struct PairOptions {
    double ppm = -1, ppp = -1;
    long long count = -1;
    std::vector<double> box;
    std::vector<double> z_range{-10, 10};
    std::string flow_file;
    std::vector<double> uniform;
    double ring_vortex_voxel_mm = 0;
    long long rays = 10000;
    double brightness_spread = 0;
  };
  auto p = std::make_shared<PairOptions>();
  add_common(cmd, *o, "output folder (created): frame_A.tif, frame_B.tif, particles_A.csv, particles_B.csv, flow.yaml");
  auto* density = cmd->add_option_group("density", "how many particles (one of)");
  density->add_option("--ppm", p->ppm, "particles per microlens in the field of view");
  density->add_option("--ppp", p->ppp, "particles per pixel in the field of view");
  density->add_option("--count", p->count, "particles in the box");
  density->require_option(1);
  cmd->add_option("--box", p->box, "particle box x0,x1,y0,y1,z0,z1 in mm (default: field of view x --z-range)")
      ->delimiter(',')
      ->expected(6);
  cmd->add_option("--z-range", p->z_range, "depth range z0,z1 of the default box, mm")->delimiter(',')->expected(2);
  auto* flow = cmd->add_option_group("flow", "the displacement from A to B (one of)");
  flow->add_option("--flow", p->flow_file,
                   "flow YAML file (type: uniform | ring_vortex | solid_body_rotation | linear_shear)");
  flow->add_option("--uniform", p->uniform, "uniform displacement dx,dy,dz in mm")->delimiter(',')->expected(3);
  flow->add_option("--ring-vortex", p->ring_vortex_voxel_mm,
                   "paper's ring vortex (eqs 15-16) at the box centre, in voxels of this size (mm)");
  flow->require_option(1);
  cmd->add_option("--rays", p->rays, "rays per particle")->capture_default_str();
  add_brightness_option(cmd, p->brightness_spread);

  cmd->callback([o, p] {
    const auto limit = thread_limit(o->threads);
    const optics::CameraModel camera = optics::load_camera_file(o->camera);
    const std::uint64_t seed = seed_of(*o);
    sim::RenderOptions options;
    options.rays_per_particle = ray_count(p->rays, "--rays");
    options.diffraction_sigma_mm = diffraction_mm(*o);
    options.sensor = o->sensor;
    // A particle's brightness from the seed and its index: the same in both frames.
    options.brightness_spread = p->brightness_spread;
    options.brightness_seed = seed;

    const sim::Box box = p->box.empty()
                             ? sim::field_of_view_box(camera, p->z_range[0], p->z_range[1])
                             : sim::Box{{p->box[0], p->box[2], p->box[4]}, {p->box[1], p->box[3], p->box[5]}};
    std::size_t count = 0;
    if (p->ppm >= 0) {
      count = sim::particle_count_from_ppm(camera, box, p->ppm);
    } else if (p->ppp >= 0) {
      count = sim::particle_count_from_ppp(camera, box, p->ppp);
    } else if (p->count >= 0) {
      count = std::size_t(p->count);
    } else {
      throw InputError("--ppm, --ppp or --count: must be >= 0");
    }

    std::unique_ptr<sim::Flow> flow;
    if (!p->flow_file.empty()) {
      flow = sim::make_flow(YamlMap(load_yaml_file(p->flow_file), p->flow_file));
    } else if (!p->uniform.empty()) {
      flow = std::make_unique<sim::UniformFlow>(sim::Point3{p->uniform[0], p->uniform[1], p->uniform[2]});
    } else {
      sim::RingVortexFlow::Parameters rv;
      for (int a = 0; a < 3; ++a) rv.centre_mm[a] = 0.5 * (box.min_mm[a] + box.max_mm[a]);
      if (!(p->ring_vortex_voxel_mm > 0)) throw InputError("--ring-vortex: the voxel size must be > 0 mm");
      rv.voxel_mm = p->ring_vortex_voxel_mm;
      flow = std::make_unique<sim::RingVortexFlow>(rv);
    }

    const std::filesystem::path dir = o->output;
    const auto a = sim::random_particles(box, count, seed);
    const auto b = sim::displace(a, *flow);
    const auto array = true_array(camera, *o);
    // Frame seeds: derived from the seed so A and B carry independent ray and sensor noise.
    const auto ra = render_with_progress(camera, array, a, options, seed * 2 + 1, "frame A");
    const auto rb = render_with_progress(camera, array, b, options, seed * 2 + 2, "frame B");
    // Created once both frames are rendered: options that cannot render leave no folder behind.
    std::filesystem::create_directories(dir);
    sim::write_particles_csv(dir / "particles_A.csv", a);
    sim::write_particles_csv(dir / "particles_B.csv", b);
    write_text(dir / "flow.yaml", flow->parameters_yaml());
    std::ostringstream meta;
    meta << "# how frame_A.tif / frame_B.tif were made (plenopiv simulate pair)\n"
         << "camera: " << o->camera << "\nseed: " << seed << "\nparticles: " << count << "\nbox_min_mm: ["
         << num(box.min_mm[0]) << ", " << num(box.min_mm[1]) << ", " << num(box.min_mm[2]) << "]\nbox_max_mm: ["
         << num(box.max_mm[0]) << ", " << num(box.max_mm[1]) << ", " << num(box.max_mm[2])
         << "]\nrays_per_particle: " << options.rays_per_particle
         << "\ndiffraction_sigma_mm: " << num(options.diffraction_sigma_mm)
         << "\nbrightness_spread: " << num(options.brightness_spread)
         << "\nbrightness_seed: " << options.brightness_seed << "\nflow: flow.yaml\n";
    write_text(dir / "simulation.yaml", meta.str());
    io::write_tiff(dir / "frame_A.tif", ra.image);
    io::write_tiff(dir / "frame_B.tif", rb.image);
    report((dir / "frame_A.tif").string(), ra.counts);
    report((dir / "frame_B.tif").string(), rb.counts);
  });
}

}  // namespace

void add_simulate_commands(CLI::App& app) {
  auto* simulate = app.add_subcommand("simulate", "ray-traced synthetic plenoptic images (paper sec 4)");
  simulate->require_subcommand(1);
  add_particles_command(*simulate);
  add_target_command(*simulate, "calibration", true);
  add_target_command(*simulate, "white", false);
  add_pair_command(*simulate);
}

}  // namespace plenopiv::client
