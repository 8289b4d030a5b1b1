// MART's depth response: what a pair's own processing measures in depth for known uniform depth
// shifts of simulated particles, per depth layer of the vector grid, and its inverse applied to w.
#include "core/process/depth_response.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <stdexcept>

#include "core/base/byte_stream.hpp"
#include "core/base/errors.hpp"
#include "core/process/pair_processor.hpp"
#include "core/sim/flows.hpp"
#include "core/sim/particles.hpp"
#include "core/sim/render.hpp"

namespace plenopiv::process {

namespace {

std::string mm(double v) {
  char text[32];
  std::snprintf(text, sizeof text, "%.3g", v);
  return text;
}

// The refusal of a layer whose vectors do not follow the shifts (DepthResponse's constructor, and
// measure_depth_response once the first shift is in): `m[k]` measured for `true_mm[k]`, the
// columns from `known` on not measured yet.
[[noreturn]] void refuse_layer(const Grid3& field_grid, std::size_t layer, const std::vector<double>& true_mm,
                               const std::vector<double>& m, std::size_t known) {
  std::string seen;
  for (std::size_t j = 0; j < m.size(); ++j)
    seen += (j ? ", " : "") + mm(true_mm[j]) + " -> " + (j < known || true_mm[j] == 0 ? mm(m[j]) : "not measured");
  const std::string least_text = mm(kDepthResponseLeast), most_text = mm(1 / kDepthResponseLeast);
  throw InputError("depth response: the vectors at z = " + mm(field_grid.coordinate_mm(2, int(layer))) +
                   " mm follow a depth shift by less than " + least_text +
                   " of it, or not at all (true -> measured mm: " + seen +
                   "), so correcting their w would multiply its noise by more than " + most_text +
                   "; turn reconstruction.depth_response_ppm off, or give the volume a depth guard or move it");
}

// Whether measured value `m` follows an outermost true shift: finite, and at least
// kDepthResponseLeast of it.
bool follows_outermost(double m, double true_mm) { return std::isfinite(m) && m / true_mm >= kDepthResponseLeast; }

// A calibration pair's motion: the depth shift, and lateral shifts that sweep one voxel across the
// particles' box (u along y, v along x), so that each layer's vectors see the sub-voxel lateral
// shifts. MART discretises a particle on the lens grid: a pair moved by whole voxels sideways (or
// not at all) is reconstructed alike in both exposures, while a fraction of a voxel changes how its
// light splits between lenses, and with it w's response and error; a flow's vectors carry every
// fraction. The vectors' nodes span less than the box (the margin, half a window at each face), so
// they see most fractions on a large box and the middle ones only on a small one (docs/accuracy.md,
// "Per-vector uncertainty"). The gradient (one voxel over the box) is far below what the window
// deformation follows.
class LateralSweep : public sim::Flow {
 public:
  LateralSweep(const sim::Box& box, const std::array<double, 3>& voxel_mm, double depth_shift_mm)
      : box_(box), voxel_mm_(voxel_mm), w_mm_(depth_shift_mm) {}
  sim::Point3 displacement_mm(const sim::Point3& p) const override {
    return {voxel_mm_[0] * (p[1] - box_.min_mm[1]) / (box_.max_mm[1] - box_.min_mm[1]),
            voxel_mm_[1] * (p[0] - box_.min_mm[0]) / (box_.max_mm[0] - box_.min_mm[0]), w_mm_};
  }
  std::string name() const override { return "depth_response_lateral_sweep"; }
  std::string parameters_yaml() const override { return "{type: " + name() + ", depth_shift_mm: " + mm(w_mm_) + "}"; }

 private:
  sim::Box box_;
  std::array<double, 3> voxel_mm_;
  double w_mm_;
};

// The scattered sets' extra motion: each particle moved sideways by its own random shift, uniform
// over one voxel in x and in y, so that every window holds every sub-voxel lateral fraction, as a
// window of a flow whose lateral motion varies across it does. A window moved by the sweep alone
// carries its one fraction's depth error (largest near focus), which such a window averages; u and
// v keep the sweep as their truth only in the unscattered sets, where no random shift adds to a
// window's mean motion.
void scatter_sideways(std::vector<sim::Point3>& particles, const std::array<double, 3>& voxel_mm, std::uint64_t seed) {
  const sim::Box one_voxel{{-0.5 * voxel_mm[0], -0.5 * voxel_mm[1], -0.5 * voxel_mm[2]},
                           {0.5 * voxel_mm[0], 0.5 * voxel_mm[1], 0.5 * voxel_mm[2]}};
  const std::vector<sim::Point3> shifts = sim::random_particles(one_voxel, particles.size(), seed + 1);
  for (std::size_t i = 0; i < particles.size(); ++i) {
    particles[i][0] += shifts[i][0];
    particles[i][1] += shifts[i][1];
  }
}

}  // namespace

DepthResponse::DepthResponse(Grid3 field_grid, std::vector<double> true_mm,
                             std::vector<std::vector<double>> measured_mm, std::vector<SigmaWidening> widening)
    : field_grid_(field_grid),
      true_mm_(std::move(true_mm)),
      measured_mm_(std::move(measured_mm)),
      widening_(std::move(widening)) {
  if (true_mm_.size() < 2 || !std::is_sorted(true_mm_.begin(), true_mm_.end()) ||
      std::adjacent_find(true_mm_.begin(), true_mm_.end()) != true_mm_.end())
    throw std::logic_error("DepthResponse: the true shifts must be at least two, ascending and distinct");
  if (measured_mm_.size() != std::size_t(field_grid_.shape[2]))
    throw std::logic_error("DepthResponse: one row of measured shifts per depth layer of the vector grid");
  if (!widening_.empty() && widening_.size() != measured_mm_.size())
    throw std::logic_error("DepthResponse: one sigma widening per depth layer of the vector grid, or none");
  for (const SigmaWidening& w : widening_)
    if (!(std::isfinite(w.scale_u) && w.scale_u >= 1 && std::isfinite(w.scale_v) && w.scale_v >= 1 &&
          std::isfinite(w.unseen_w_mm) && w.unseen_w_mm >= 0))
      throw std::logic_error(
          "DepthResponse: a sigma widening's scales must be finite and at least 1, its unseen w finite and not "
          "negative");
  for (std::size_t layer = 0; layer < measured_mm_.size(); ++layer) {
    const std::vector<double>& m = measured_mm_[layer];
    if (m.size() != true_mm_.size()) throw std::logic_error("DepthResponse: one measured shift per true shift");
    std::vector<double> curve = m;
    for (std::size_t k = 0; k < m.size(); ++k) {
      const bool rises = k + 1 == m.size() || m[k + 1] > m[k];
      const bool outermost = k == 0 || k + 1 == m.size();
      const double least = kDepthResponseLeast * true_mm_[k];
      const bool follows = true_mm_[k] == 0 ? m[k] == 0 : !outermost || follows_outermost(m[k], true_mm_[k]);
      if (std::isfinite(m[k]) && rises && follows) {
        // Rising through (0, 0), an inner value lies on its shift's side of 0; raised to `least`
        // it still lies below the outermost value on that side, so the curve still rises.
        if (true_mm_[k] != 0 && std::abs(m[k]) < std::abs(least)) curve[k] = least;
        continue;
      }
      refuse_layer(field_grid_, layer, true_mm_, m, m.size());
    }
    curve_mm_.push_back(std::move(curve));
  }
}

int DepthResponse::segment(int layer, double measured_mm) const {
  const std::vector<double>& m = curve_mm_[std::size_t(layer)];
  // The first segment whose upper end lies above the value, the last one for values beyond it.
  int k = 0;
  while (k + 2 < int(m.size()) && measured_mm > m[std::size_t(k) + 1]) ++k;
  return k;
}

double DepthResponse::segment_slope(int layer, int k) const {
  const std::vector<double>& m = curve_mm_[std::size_t(layer)];
  return (true_mm_[std::size_t(k) + 1] - true_mm_[std::size_t(k)]) / (m[std::size_t(k) + 1] - m[std::size_t(k)]);
}

double DepthResponse::along_segment(int layer, int k, double measured_mm) const {
  return true_mm_[std::size_t(k)] +
         (measured_mm - curve_mm_[std::size_t(layer)][std::size_t(k)]) * segment_slope(layer, k);
}

double DepthResponse::true_mm(int layer, double measured_mm) const {
  return along_segment(layer, segment(layer, measured_mm), measured_mm);
}

double DepthResponse::slope(int layer, double measured_mm) const {
  return segment_slope(layer, segment(layer, measured_mm));
}

void DepthResponse::apply(VectorField& field) const {
  const Grid3& g = field.grid;
  if (g.shape[2] != field_grid_.shape[2] || g.origin_mm[2] != field_grid_.origin_mm[2] ||
      g.spacing_mm[2] != field_grid_.spacing_mm[2])
    throw std::logic_error("DepthResponse::apply: the field's depth layers are not those the response was measured on");
  const bool with_sigma = field.has_sigma();
  if (with_sigma)
    field.sigma_method += widening_.empty()
                              ? "; w's carried through MART's depth response"
                              : "; widened per depth layer to the error beyond it of MART's depth response pairs "
                                "(simulated with this camera and these settings: Timmins et al. 2012), w's then "
                                "carried through the response";
  const std::size_t per_layer = std::size_t(g.shape[0]) * std::size_t(g.shape[1]);
  for (int layer = 0; layer < g.shape[2]; ++layer) {
    const SigmaWidening widen = widening_.empty() ? SigmaWidening{} : widening_[std::size_t(layer)];
    for (std::size_t i = std::size_t(layer) * per_layer; i < std::size_t(layer + 1) * per_layer; ++i) {
      const double w = field.dz_mm[i];
      if (!std::isfinite(w)) continue;
      const int k = segment(layer, w);  // once per vector: value and slope come from the same segment
      if (with_sigma) {                 // NaN (no estimate) stays NaN
        field.sigma_dx_mm[i] = float(double(field.sigma_dx_mm[i]) * widen.scale_u);
        field.sigma_dy_mm[i] = float(double(field.sigma_dy_mm[i]) * widen.scale_v);
        field.sigma_dz_mm[i] =
            float(std::hypot(double(field.sigma_dz_mm[i]), widen.unseen_w_mm) * segment_slope(layer, k));
      }
      field.dz_mm[i] = float(along_segment(layer, k, w));
    }
  }
}

std::string DepthResponse::summary() const {
  std::string text = "depth response over z " + mm(field_grid_.coordinate_mm(2, 0)) + ".." +
                     mm(field_grid_.coordinate_mm(2, field_grid_.shape[2] - 1)) + " mm:";
  for (const std::size_t k : {true_mm_.size() - 1, std::size_t(0)}) {
    double lo = 1e9, hi = -1e9;
    for (const std::vector<double>& m : measured_mm_) {
      lo = std::min(lo, m[k] / true_mm_[k]);
      hi = std::max(hi, m[k] / true_mm_[k]);
    }
    text += (k ? " " : ", ") + mm(lo) + ".." + mm(hi) + " of " + (true_mm_[k] > 0 ? "+" : "") + mm(true_mm_[k]) + " mm";
  }
  int raised = 0, first = -1, last = -1;
  for (std::size_t layer = 0; layer < curve_mm_.size(); ++layer)
    for (std::size_t k = 0; k < true_mm_.size(); ++k)
      if (curve_mm_[layer][k] != measured_mm_[layer][k]) {
        ++raised;
        if (first < 0) first = int(layer);
        last = int(layer);
      }
  if (raised)
    text += "; " + std::to_string(raised) + " inner shift" + (raised > 1 ? "s" : "") + " over z " +
            mm(field_grid_.coordinate_mm(2, first)) + ".." + mm(field_grid_.coordinate_mm(2, last)) +
            " mm measured as less than " + mm(kDepthResponseLeast) + " of it, taken as that (w there under-corrected)";
  if (!widening_.empty()) {
    SigmaWidening most;
    for (const SigmaWidening& w : widening_) {
      most.scale_u = std::max(most.scale_u, w.scale_u);
      most.scale_v = std::max(most.scale_v, w.scale_v);
      most.unseen_w_mm = std::max(most.unseen_w_mm, w.unseen_w_mm);
    }
    text += "; sigma widened to the simulated pairs' error, u up to x" + mm(most.scale_u) + ", v up to x" +
            mm(most.scale_v) + ", w by up to " + mm(most.unseen_w_mm) + " mm in quadrature";
  }
  return text;
}

void DepthResponse::serialize(std::string& out) const {
  ByteWriter w(out);
  w.pod(field_grid_.shape);
  w.pod(field_grid_.origin_mm);
  w.pod(field_grid_.spacing_mm);
  w.vec(true_mm_);
  for (const std::vector<double>& m : measured_mm_) w.vec(m);
  w.vec(widening_);
}

DepthResponse DepthResponse::deserialize(std::string_view bytes) {
  ByteReader r("depth response bytes", bytes);
  Grid3 grid;
  grid.shape = r.pod<std::array<int, 3>>();
  grid.origin_mm = r.pod<std::array<double, 3>>();
  grid.spacing_mm = r.pod<std::array<double, 3>>();
  std::vector<double> true_mm;
  r.vec(true_mm);
  // Each layer's row takes at least its count's 8 bytes.
  if (grid.shape[2] < 1 || std::size_t(grid.shape[2]) > (bytes.size() - r.at()) / sizeof(std::uint64_t))
    r.fail(std::to_string(grid.shape[2]) + " depth layers do not fit the bytes");
  std::vector<std::vector<double>> measured(std::size_t(grid.shape[2]));
  for (std::vector<double>& m : measured) r.vec(m);
  std::vector<SigmaWidening> widening;
  r.vec(widening);
  if (!r.done()) r.fail("bytes left after the response");
  try {
    return DepthResponse(grid, std::move(true_mm), std::move(measured), std::move(widening));
  } catch (const std::exception& e) {  // the constructor's checks: InputError or std::logic_error
    r.fail(e.what());
  }
}

DepthResponse measure_depth_response(const PairProcessor& processor, const optics::CameraModel& camera,
                                     const optics::MicrolensArray& lenses, double seeding_ppm,
                                     const std::function<void(double)>& progress) {
  const ProcessSettings& s = processor.settings();
  const Grid3 g = s.reconstruction_grid();
  // The reconstructed box (guard slices included) and 1 mm beyond each face: particles just outside
  // it light its edges, as in any real flow.
  sim::Box box;
  for (std::size_t a = 0; a < 3; ++a) {
    box.min_mm[a] = g.origin_mm[a] - 0.5 * g.spacing_mm[a] - 1.0;
    box.max_mm[a] = g.origin_mm[a] + (g.shape[a] - 0.5) * g.spacing_mm[a] + 1.0;
  }
  const std::size_t count = sim::particle_count_from_ppm(camera, box, seeding_ppm);
  sim::RenderOptions render;
  render.rays_per_particle = 5000;  // the frames' ray noise well below the sensor's

  std::vector<double> shifts_mm{0.0};
  for (const double v : kDepthResponseShiftsVoxel) shifts_mm.push_back(v * s.grid.spacing_mm[2]);
  std::sort(shifts_mm.begin(), shifts_mm.end());
  const std::size_t shifts = shifts_mm.size() - 1;  // the 0 shift needs no pair

  // Per depth layer and shift: the sum of the valid vectors' w and their count, over the shift's
  // particle sets (each set its own particles and sensor noise).
  Grid3 field_grid;
  std::vector<std::vector<double>> sum, count_valid;
  // Per depth layer and shift, over the valid vectors with a sigma, summed (the widening's
  // terms): of the sets as they are, their count, the squared errors of u and v and their sigma^2;
  // of the scattered sets, their count, w, w^2 and w's sigma^2.
  enum Term { kCountUV, kU2, kV2, kSigmaU2, kSigmaV2, kCountW, kW, kW2, kSigmaW2, kTerms };
  std::vector<std::vector<std::array<double, kTerms>>> spread;
  // A layer's mean w for shift k over its valid vectors; NaN without any.
  const auto mean_of = [&](std::size_t layer, std::size_t k) {
    return count_valid[layer][k] > 0 ? sum[layer][k] / count_valid[layer][k] : std::nan("");
  };
  bool with_sigma = true;
  int sets = 1;  // per shift, known after the first pair (it depends on the vectors per layer)
  std::size_t sets_done = 0;
  // The fraction done at a point of the current set's pass (`scattered` or not) `pair_fraction` of
  // the way through its pair: 0 during the first pair, before the count of sets is known.
  const auto done_at = [&](bool scattered, double pair_fraction) {
    return sum.empty() ? 0.0
                       : (double(sets_done) + 0.5 * ((scattered ? 1.0 : 0.0) + pair_fraction)) /
                             double(shifts * std::size_t(sets));
  };
  // A frame, tracing its rays (seconds at the paper's scale) with the caller told the fraction
  // done so far about every 1 % of the particles (on this thread, as render tells its progress):
  // where it can end the measurement, as after a MART iteration.
  const auto frame = [&](const std::vector<sim::Point3>& particles, std::uint64_t seed, double fraction) {
    sim::RenderOptions o = render;
    if (progress) o.progress = [&, fraction](double) { progress(fraction); };
    return sim::render(camera, lenses, particles, o, seed).image;
  };
  for (std::size_t k = 0; k < shifts_mm.size(); ++k) {
    if (shifts_mm[k] == 0.0) continue;
    for (int set = 0; set < sets; ++set) {
      const std::uint64_t seed = 7001 + 2 * std::uint64_t(sets_done);
      const std::vector<sim::Point3> a = sim::random_particles(box, count, seed);
      const LateralSweep flow(box, s.grid.spacing_mm, shifts_mm[k]);
      const ImageU16 frame_a = frame(a, seed, done_at(false, 0.0));
      const std::vector<sim::Point3> swept = sim::displace(a, flow);
      // Each set twice: as the sweep moves it (the gain, and u's and v's error), then with every
      // particle also moved sideways at random (w's error about the layer's mean).
      for (const bool scattered : {false, true}) {
        std::vector<sim::Point3> b = swept;
        if (scattered) scatter_sideways(b, s.grid.spacing_mm, seed);
        // Within a pair, after every MART iteration and correlation pass, the fraction so far:
        // where a caller can end it.
        PairOptions options;
        if (progress)
          options.progress = [&](const std::string&, double pair_fraction) {
            progress(done_at(scattered, pair_fraction));
          };
        const PairResult r =
            processor.process_uncorrected(frame_a, frame(b, seed + 1, done_at(scattered, 0.0)), options);
        const VectorField& f = r.correlation.field;
        const std::size_t per_layer = std::size_t(f.grid.shape[0]) * std::size_t(f.grid.shape[1]);
        if (sum.empty()) {
          field_grid = f.grid;
          sum.assign(std::size_t(f.grid.shape[2]), std::vector<double>(shifts_mm.size(), 0.0));
          count_valid = sum;
          spread.assign(sum.size(),
                        std::vector<std::array<double, kTerms>>(shifts_mm.size(), std::array<double, kTerms>{}));
          sets = int(std::clamp<std::size_t>((kDepthResponseVectorsPerLayer + per_layer - 1) / per_layer, 1,
                                             kDepthResponseMostSets));
        }
        with_sigma = with_sigma && f.has_sigma();
        for (int z = 0; z < f.grid.shape[2]; ++z)
          for (int y = 0; y < f.grid.shape[1]; ++y)
            for (int x = 0; x < f.grid.shape[0]; ++x) {
              const std::size_t i = f.grid.index(x, y, z);
              if (!f.valid[i] || !std::isfinite(f.dz_mm[i])) continue;
              if (!scattered) {
                sum[std::size_t(z)][k] += f.dz_mm[i];
                count_valid[std::size_t(z)][k] += 1;
              }
              if (!with_sigma || !std::isfinite(f.sigma_dx_mm[i]) || !std::isfinite(f.sigma_dy_mm[i]) ||
                  !std::isfinite(f.sigma_dz_mm[i]))
                continue;
              std::array<double, kTerms>& t = spread[std::size_t(z)][k];
              if (scattered) {
                const double w = f.dz_mm[i], sw = f.sigma_dz_mm[i];
                t[kCountW] += 1;
                t[kW] += w;
                t[kW2] += w * w;
                t[kSigmaW2] += sw * sw;
              } else {
                const sim::Point3 truth = flow.displacement_mm(
                    {f.grid.coordinate_mm(0, x), f.grid.coordinate_mm(1, y), f.grid.coordinate_mm(2, z)});
                const double u = f.dx_mm[i] - truth[0], v = f.dy_mm[i] - truth[1];
                const double su = f.sigma_dx_mm[i], sv = f.sigma_dy_mm[i];
                t[kCountUV] += 1;
                t[kU2] += u * u;
                t[kV2] += v * v;
                t[kSigmaU2] += su * su;
                t[kSigmaV2] += sv * sv;
              }
            }
        if (progress) progress((double(sets_done) + (scattered ? 1.0 : 0.5)) / double(shifts * std::size_t(sets)));
      }
      ++sets_done;
    }
    // The first shift is an outermost one: a layer that does not follow it is refused by the
    // response whatever the other shifts show, so the pairs left are not processed.
    if (k == 0)
      for (std::size_t layer = 0; layer < sum.size(); ++layer)
        if (!follows_outermost(mean_of(layer, 0), shifts_mm[0])) {
          std::vector<double> known(shifts_mm.size(), 0.0);
          known[0] = mean_of(layer, 0);
          refuse_layer(field_grid, layer, shifts_mm, known, 1);
        }
  }
  std::vector<std::vector<double>> measured(sum.size(), std::vector<double>(shifts_mm.size(), 0.0));
  for (std::size_t layer = 0; layer < sum.size(); ++layer)
    for (std::size_t k = 0; k < shifts_mm.size(); ++k)
      if (shifts_mm[k] != 0.0) measured[layer][k] = mean_of(layer, k);
  // Pooled over the shifts: u's and v's RMS error about the sweep over their RMS sigma; w's mean
  // square error about its shift's mean over the scattered sets less its mean square sigma.
  std::vector<SigmaWidening> widening;
  if (with_sigma)
    for (const std::vector<std::array<double, kTerms>>& layer : spread) {
      std::array<double, kTerms> sum_of{};
      for (const std::array<double, kTerms>& t : layer) {
        for (const Term term : {kCountUV, kU2, kV2, kSigmaU2, kSigmaV2}) sum_of[term] += t[term];
        if (t[kCountW] == 0) continue;
        sum_of[kCountW] += t[kCountW];
        sum_of[kW2] += t[kW2] - t[kW] * t[kW] / t[kCountW];
        sum_of[kSigmaW2] += t[kSigmaW2];
      }
      const auto scale = [](double error2, double sigma2) {
        return sigma2 > 0 ? std::max(1.0, std::sqrt(error2 / sigma2)) : 1.0;
      };
      SigmaWidening& w = widening.emplace_back();
      w.scale_u = scale(sum_of[kU2], sum_of[kSigmaU2]);
      w.scale_v = scale(sum_of[kV2], sum_of[kSigmaV2]);
      if (sum_of[kCountW] > 0)
        w.unseen_w_mm = std::sqrt(std::max(0.0, (sum_of[kW2] - sum_of[kSigmaW2]) / sum_of[kCountW]));
    }
  return DepthResponse(field_grid, shifts_mm, std::move(measured), std::move(widening));
}

}  // namespace plenopiv::process
