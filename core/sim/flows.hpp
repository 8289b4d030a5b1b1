// Displacement fields that move particle field A into field B, each with its exact displacement.
#pragma once

#include <memory>
#include <string>
#include <vector>

#include "core/base/yaml_access.hpp"
#include "core/sim/particles.hpp"

namespace plenopiv::sim {

// A displacement field in object space: the truth accuracy tests compare against.
class Flow {
 public:
  virtual ~Flow();
  // Exact displacement (mm) of a particle at p_mm between exposure A and exposure B.
  virtual Point3 displacement_mm(const Point3& p_mm) const = 0;
  // The `type` key of the flow's YAML ("uniform", "ring_vortex", ...).
  virtual std::string name() const = 0;
  // The flow as a YAML mapping that make_flow() reads back into the same flow.
  virtual std::string parameters_yaml() const = 0;
};

// The same displacement everywhere.
class UniformFlow : public Flow {
 public:
  explicit UniformFlow(const Point3& d_mm);
  Point3 displacement_mm(const Point3& p_mm) const override;
  std::string name() const override { return "uniform"; }
  std::string parameters_yaml() const override;

 private:
  Point3 d_mm_;
};

// Gaussian ring vortex, paper eqs 15-16 with the readings of DESIGN.md "Notes on the reference
// text". A ring of diameter D (8 mm in the paper) centred at `centre_mm`, axis along y, lying in
// the x-z plane. For a point p, rho = its distance to the y axis through the centre and h = its
// height along y; in the meridional half-plane (through the axis and p) the core circle is at
// (rho, h) = (D/2, 0) and r = |(rho - D/2, h)| is the distance to the core circle. In voxels:
//   V_theta(r) = -Gamma / (2 pi r) (1 - exp(-r^2 / c_theta))           (eq 15)
//   c_theta = r_c^2 / gamma,  Gamma = 2 pi r_c v_rc / (1 - exp(-gamma))
// Gamma is chosen so that |V_theta(r_c)| = v_rc (eq 16 as printed is not a circulation; see
// DESIGN.md); gamma = 1.256431 puts the maximum of |V_theta| at r = r_c. The displacement is
// V_theta e_theta, with e_theta = (-h, rho - D/2) / r in the (e_rho, e_y) basis: the radial
// offset from the core turned by +90 degrees towards +y. With the minus sign of eq 15 the ring
// moves fluid through its centre along +y (down on the image). On the axis (rho = 0) e_rho is
// undefined; there the radial component is set to 0 (the y component is well defined).
// r_c, v_rc in voxels of edge voxel_mm; displacements returned in mm.
class RingVortexFlow : public Flow {
 public:
  struct Parameters {
    Point3 centre_mm{0, 0, 0};
    double ring_diameter_mm = 8.0;
    double voxel_mm = 0.1;
    double core_radius_voxels = 40.0;       // r_c
    double core_displacement_voxels = 8.0;  // v_rc, |V_theta| at r = r_c
    double gamma = 1.256431;
  };
  explicit RingVortexFlow(const Parameters& p);
  Point3 displacement_mm(const Point3& p_mm) const override;
  std::string name() const override { return "ring_vortex"; }
  std::string parameters_yaml() const override;

  // Signed tangential displacement of eq 15 (voxels) at distance r (voxels) from the core.
  double tangential_voxels(double r_voxels) const;
  double circulation() const { return circulation_; }  // Gamma, voxel^2
  const Parameters& parameters() const { return p_; }

 private:
  Parameters p_;
  double circulation_;
  double c_theta_;
};

// Rigid rotation by `angle_rad` (right-handed) about the axis through `centre_mm` along `axis`:
// displacement = R (p - c) - (p - c), exact for any angle.
class SolidBodyRotation : public Flow {
 public:
  SolidBodyRotation(const Point3& centre_mm, const Point3& axis, double angle_rad);
  Point3 displacement_mm(const Point3& p_mm) const override;
  std::string name() const override { return "solid_body_rotation"; }
  std::string parameters_yaml() const override;

 private:
  Point3 centre_mm_;
  Point3 axis_;  // unit
  double angle_rad_;
};

// Linear shear: displacement = rate_per_mm * (p[gradient_axis] - reference_mm), e.g.
// rate (0.01, 0, 0) with gradient_axis 1 moves each x-z layer along x by 0.01 mm per mm of y.
class LinearShear : public Flow {
 public:
  LinearShear(const Point3& rate_per_mm, int gradient_axis, double reference_mm);
  Point3 displacement_mm(const Point3& p_mm) const override;
  std::string name() const override { return "linear_shear"; }
  std::string parameters_yaml() const override;

 private:
  Point3 rate_per_mm_;
  int gradient_axis_;
  double reference_mm_;
};

// Builds a flow from a YAML mapping with `type` one of uniform, ring_vortex,
// solid_body_rotation, linear_shear and that flow's keys:
//   uniform:             displacement_mm: [dx, dy, dz]
//   ring_vortex:         centre_mm: [x, y, z], ring_diameter_mm (8), voxel_mm (0.1),
//                        core_radius_voxels (40), core_displacement_voxels (8), gamma (1.256431)
//   solid_body_rotation: centre_mm: [x, y, z], axis: [ax, ay, az], angle_rad
//   linear_shear:        rate_per_mm: [rx, ry, rz], gradient_axis: x|y|z, reference_mm (0)
// Unknown type or key, a missing required key, a malformed vector: InputError naming the key.
std::unique_ptr<Flow> make_flow(const YamlMap& map);

// Field B from field A: p + flow.displacement_mm(p) for each particle, in order.
std::vector<Point3> displace(const std::vector<Point3>& particles, const Flow& flow);

}  // namespace plenopiv::sim
