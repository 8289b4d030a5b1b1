// Displacement fields that move particle field A into field B, each with its exact displacement.
#include "core/sim/flows.hpp"

#include <charconv>
#include <cmath>
#include <numbers>

#include "core/base/errors.hpp"

namespace plenopiv::sim {
namespace {

// Round-trip precision: parameters_yaml() must give back the same flow.
std::string num(double v) {
  char buf[40];
  const auto end = std::to_chars(buf, buf + sizeof buf, v).ptr;  // shortest exact form
  return std::string(buf, end);
}
std::string vec(const Point3& p) { return "[" + num(p[0]) + ", " + num(p[1]) + ", " + num(p[2]) + "]"; }

Point3 read_vector(const YamlMap& map, std::string_view key) {
  const YAML::Node node = map.node()[std::string(key)];
  if (!node) map.fail(key, "missing (required key), expected [x, y, z]");
  if (!node.IsSequence() || node.size() != 3) map.fail(key, "expected a list of 3 numbers [x, y, z]");
  Point3 p{};
  for (std::size_t i = 0; i < 3; ++i) {
    try {
      p[i] = node[i].as<double>();
    } catch (const YAML::Exception&) {
      map.fail(key, "element " + std::to_string(i) + " is not a number");
    }
    if (!std::isfinite(p[i])) map.fail(key, "element " + std::to_string(i) + " is not finite");
  }
  return p;
}

Point3 read_vector_or(const YamlMap& map, std::string_view key, const Point3& fallback) {
  return map.has(key) ? read_vector(map, key) : fallback;
}

double positive(const YamlMap& map, std::string_view key, double fallback) {
  const double v = map.number_or(key, fallback);
  if (!(v > 0)) map.fail(key, "must be > 0, got " + num(v));
  return v;
}

}  // namespace

Flow::~Flow() = default;

UniformFlow::UniformFlow(const Point3& d_mm) : d_mm_(d_mm) {}
Point3 UniformFlow::displacement_mm(const Point3&) const { return d_mm_; }
std::string UniformFlow::parameters_yaml() const { return "type: uniform\ndisplacement_mm: " + vec(d_mm_) + "\n"; }

RingVortexFlow::RingVortexFlow(const Parameters& p) : p_(p) {
  if (!(p.ring_diameter_mm > 0) || !(p.voxel_mm > 0) || !(p.core_radius_voxels > 0) || !(p.gamma > 0)) {
    throw InputError("ring vortex: ring_diameter_mm, voxel_mm, core_radius_voxels and gamma must be > 0");
  }
  circulation_ = 2 * std::numbers::pi * p.core_radius_voxels * p.core_displacement_voxels / (1 - std::exp(-p.gamma));
  c_theta_ = p.core_radius_voxels * p.core_radius_voxels / p.gamma;
}

double RingVortexFlow::tangential_voxels(double r) const {
  // (1 - e^{-r^2/c}) / r -> r / c as r -> 0: the core does not move.
  if (r < 1e-12) return 0.0;
  return -circulation_ / (2 * std::numbers::pi * r) * -std::expm1(-r * r / c_theta_);
}

Point3 RingVortexFlow::displacement_mm(const Point3& p_mm) const {
  const double qx = p_mm[0] - p_.centre_mm[0];
  const double qy = p_mm[1] - p_.centre_mm[1];
  const double qz = p_mm[2] - p_.centre_mm[2];
  const double rho = std::hypot(qx, qz);
  const double d_rho = rho - 0.5 * p_.ring_diameter_mm;  // offset from the core, in-plane
  const double r_mm = std::hypot(d_rho, qy);
  if (r_mm < 1e-12) return {0, 0, 0};
  const double v_mm = tangential_voxels(r_mm / p_.voxel_mm) * p_.voxel_mm;
  // e_theta = (-qy, d_rho) / r in the (e_rho, e_y) basis.
  const double radial = v_mm * -qy / r_mm;
  const double axial = v_mm * d_rho / r_mm;
  const double ex = rho > 0 ? qx / rho : 0.0, ez = rho > 0 ? qz / rho : 0.0;
  return {radial * ex, axial, radial * ez};
}

std::string RingVortexFlow::parameters_yaml() const {
  return "type: ring_vortex\ncentre_mm: " + vec(p_.centre_mm) + "\nring_diameter_mm: " + num(p_.ring_diameter_mm) +
         "\nvoxel_mm: " + num(p_.voxel_mm) + "\ncore_radius_voxels: " + num(p_.core_radius_voxels) +
         "\ncore_displacement_voxels: " + num(p_.core_displacement_voxels) + "\ngamma: " + num(p_.gamma) +
         "\n# Gamma = 2 pi r_c v_rc / (1 - exp(-gamma)) = " + num(circulation_) +
         " voxel^2, so that |V_theta(r_c)| = v_rc\n";
}

SolidBodyRotation::SolidBodyRotation(const Point3& centre_mm, const Point3& axis, double angle_rad)
    : centre_mm_(centre_mm), angle_rad_(angle_rad) {
  const double n = std::sqrt(axis[0] * axis[0] + axis[1] * axis[1] + axis[2] * axis[2]);
  if (!(n > 0) || !std::isfinite(n)) throw InputError("solid_body_rotation: axis must be a non-zero vector");
  axis_ = {axis[0] / n, axis[1] / n, axis[2] / n};
}

Point3 SolidBodyRotation::displacement_mm(const Point3& p) const {
  // Rodrigues: R v = v cos + (k x v) sin + k (k.v)(1 - cos).
  const Point3 v{p[0] - centre_mm_[0], p[1] - centre_mm_[1], p[2] - centre_mm_[2]};
  const Point3& k = axis_;
  const double c = std::cos(angle_rad_), s = std::sin(angle_rad_);
  const double kv = k[0] * v[0] + k[1] * v[1] + k[2] * v[2];
  const Point3 kxv{k[1] * v[2] - k[2] * v[1], k[2] * v[0] - k[0] * v[2], k[0] * v[1] - k[1] * v[0]};
  Point3 d;
  for (int a = 0; a < 3; ++a) d[a] = v[a] * (c - 1) + kxv[a] * s + k[a] * kv * (1 - c);
  return d;
}

std::string SolidBodyRotation::parameters_yaml() const {
  return "type: solid_body_rotation\ncentre_mm: " + vec(centre_mm_) + "\naxis: " + vec(axis_) +
         "\nangle_rad: " + num(angle_rad_) + "\n";
}

LinearShear::LinearShear(const Point3& rate_per_mm, int gradient_axis, double reference_mm)
    : rate_per_mm_(rate_per_mm), gradient_axis_(gradient_axis), reference_mm_(reference_mm) {
  if (gradient_axis < 0 || gradient_axis > 2) throw InputError("linear_shear: gradient_axis must be x, y or z");
}

Point3 LinearShear::displacement_mm(const Point3& p) const {
  const double s = p[gradient_axis_] - reference_mm_;
  return {rate_per_mm_[0] * s, rate_per_mm_[1] * s, rate_per_mm_[2] * s};
}

std::string LinearShear::parameters_yaml() const {
  static const char* axes[3] = {"x", "y", "z"};
  return "type: linear_shear\nrate_per_mm: " + vec(rate_per_mm_) + "\ngradient_axis: " + axes[gradient_axis_] +
         "\nreference_mm: " + num(reference_mm_) + "\n";
}

std::unique_ptr<Flow> make_flow(const YamlMap& map) {
  const std::string type = map.string("type");
  if (type != "uniform" && type != "ring_vortex" && type != "solid_body_rotation" && type != "linear_shear") {
    map.fail("type",
             "unknown flow '" + type + "'; expected one of uniform, ring_vortex, solid_body_rotation, linear_shear");
  }
  if (type == "uniform") {
    map.reject_unknown({"type", "displacement_mm"});
    return std::make_unique<UniformFlow>(read_vector(map, "displacement_mm"));
  }
  if (type == "ring_vortex") {
    map.reject_unknown({"type", "centre_mm", "ring_diameter_mm", "voxel_mm", "core_radius_voxels",
                        "core_displacement_voxels", "gamma"});
    RingVortexFlow::Parameters p;
    p.centre_mm = read_vector_or(map, "centre_mm", p.centre_mm);
    p.ring_diameter_mm = positive(map, "ring_diameter_mm", p.ring_diameter_mm);
    p.voxel_mm = positive(map, "voxel_mm", p.voxel_mm);
    p.core_radius_voxels = positive(map, "core_radius_voxels", p.core_radius_voxels);
    p.core_displacement_voxels = map.number_or("core_displacement_voxels", p.core_displacement_voxels);
    p.gamma = positive(map, "gamma", p.gamma);
    return std::make_unique<RingVortexFlow>(p);
  }
  if (type == "solid_body_rotation") {
    map.reject_unknown({"type", "centre_mm", "axis", "angle_rad"});
    const Point3 axis = read_vector(map, "axis");
    if (axis[0] == 0 && axis[1] == 0 && axis[2] == 0) map.fail("axis", "must be a non-zero vector");
    return std::make_unique<SolidBodyRotation>(read_vector_or(map, "centre_mm", {0, 0, 0}), axis,
                                               map.number("angle_rad"));
  }
  map.reject_unknown({"type", "rate_per_mm", "gradient_axis", "reference_mm"});
  const std::string axis = map.choice("gradient_axis", {"x", "y", "z"});
  return std::make_unique<LinearShear>(read_vector(map, "rate_per_mm"), axis[0] - 'x',
                                       map.number_or("reference_mm", 0.0));
}

std::vector<Point3> displace(const std::vector<Point3>& particles, const Flow& flow) {
  std::vector<Point3> out(particles.size());
  for (std::size_t i = 0; i < particles.size(); ++i) {
    const Point3 d = flow.displacement_mm(particles[i]);
    out[i] = {particles[i][0] + d[0], particles[i][1] + d[1], particles[i][2] + d[2]};
  }
  return out;
}

}  // namespace plenopiv::sim
