// Microlens lattices in sensor pixels: estimated from scattered points, refined by least squares,
// and a smooth distortion on top where the data support one.
#pragma once

#include <array>
#include <cstdint>
#include <string>
#include <vector>

namespace plenopiv::calib {

// A lattice of micro-image centres on the sensor, in continuous pixel coordinates (column, row;
// integer = pixel centre), indexed from an arbitrary lens (0, 0) and unbounded: it says where
// lenses would be, not how many there are. Lens (i, j) sits at lattice coordinates a = i + h(j),
// b = j, where h(j) = 0 (rect) or 0.5 on odd rows (hex), and
//   x = ox + cos(rotation) a px + sin(rotation) b py,  y = oy - sin(rotation) a px + cos(rotation) b py
// (the rotation of optics::Lattice: counter-clockwise on the upright image).
struct RawLattice {
  bool hex = false;
  double px = 0, py = 0;  // pitch along a row and row spacing, pixels
  double rotation = 0;    // rad
  double ox = 0, oy = 0;  // lens (0, 0), pixels

  double shift(int j) const { return hex && (j & 1) ? 0.5 : 0.0; }
  std::array<double, 2> at(double a, double b) const;
  std::array<double, 2> site(int i, int j) const { return at(i + shift(j), j); }
  // Lattice coordinates (a, b) of a point.
  std::array<double, 2> coords(double x, double y) const;
  // The lens whose Voronoi cell holds (x, y) (exact for rect and hex). The second form takes
  // cos and sin of the rotation, for loops over many pixels.
  std::array<int, 2> nearest(double x, double y) const;
  std::array<int, 2> nearest(double x, double y, double cos_rotation, double sin_rotation) const;
};

// Pitch, rotation and phase from points that mostly sit on one lattice (micro-image maxima,
// spots): the median in-row and next-row neighbour vectors near `pitch_px` (within 15 %,
// rotation within 14 deg), then the offset from circular means. InputError saying what was found
// when the neighbour statistics do not show a `hex` or rect lattice near that pitch.
RawLattice estimate_lattice(const std::vector<std::array<double, 2>>& points, bool hex, double pitch_px,
                            const std::string& what);

// The median distance of each point to its nearest neighbour (0 for fewer than 2 points): the
// micro-image pitch the image itself shows, whatever the camera file says.
double median_neighbour_distance(const std::vector<std::array<double, 2>>& points);

// Gauss-Newton on (ox, oy, px, py, rotation) over points assigned to lenses `ij`, each weighted by
// `weight` (0 leaves a point out). Serial: the same result at any thread count. InputError when
// the points span too few rows or columns to fix the lattice.
void refine_lattice(const std::vector<std::array<double, 2>>& points, const std::vector<std::array<int, 2>>& ij,
                    const std::vector<double>& weight, RawLattice& lattice);

// A lattice plus a smooth distortion: lens (i, j) at lattice.site(i, j) plus polynomials of total
// degree `degree` in the lattice coordinates (scaled to -1..1 over the fitted lenses, and held at
// the edge of that range beyond it).
// degree 0: the lattice alone; 1: affine (adds shear); 2, 3: bending the array.
struct LatticeModel {
  RawLattice lattice;
  int degree = 0;
  std::array<double, 2> centre{0, 0}, scale{1, 1};  // lattice coordinates -> polynomial variables
  std::vector<double> cx, cy;                       // coefficients, terms in `terms(degree)` order
  std::array<double, 2> position(int i, int j) const;
};

// The model with the lowest Bayesian information criterion over degrees 0..max_degree, fitted by
// weighted least squares to the points (lens `ij`, weight `weight`): a distortion term is kept
// only where it lowers the residual by more than its parameters explain. `degree_rss` receives
// the weighted mean square residual of each degree tried (pixels^2).
LatticeModel fit_model(const std::vector<std::array<double, 2>>& points, const std::vector<std::array<int, 2>>& ij,
                       const std::vector<double>& weight, const RawLattice& lattice, int max_degree,
                       std::vector<double>* degree_rss = nullptr);

}  // namespace plenopiv::calib
