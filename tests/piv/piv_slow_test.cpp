// Paper scale (sec 6.4): the ring vortex at 300x200x200 on exact-particle volumes, 16^3 final
// windows with 75 % overlap, RMS per component against the flow (label slow).
#include <gtest/gtest.h>

#include <cmath>

#include "core/piv/multipass.hpp"
#include "core/sim/exact_volume.hpp"
#include "core/sim/field_errors.hpp"
#include "core/sim/flows.hpp"
#include "core/sim/particles.hpp"

namespace plenopiv::piv {
namespace {

TEST(PaperScale, RingVortexOnExactParticleVolumes) {
  Grid3 g;
  g.shape = {300, 200, 200};
  g.spacing_mm = {0.1, 0.1, 0.1};
  for (int a = 0; a < 3; ++a) g.origin_mm[a] = -0.5 * (g.shape[a] - 1) * 0.1;
  const auto pa = sim::particles_around(g, 2);
  const sim::RingVortexFlow flow(sim::RingVortexFlow::Parameters{});
  const auto r = correlate_volumes(sim::render_exact_volume(g, pa),
                                   sim::render_exact_volume(g, sim::displace(pa, flow)), CorrelationSettings{});
  const auto& f = r.field;
  const sim::FieldErrors e = sim::field_errors(f, flow, 0.1);
  const auto& rms = e.rms;
  const std::size_t n = e.compared;
  std::printf("paper-scale ring vortex RMS (voxels): %.3f %.3f %.3f over %zu vectors\n", rms[0], rms[1], rms[2], n);
  EXPECT_EQ(n, f.grid.count());
  // The default correlation on exact-particle volumes, over all vectors (the paper's
  // reconstructed volumes: 0.165, 0.23, 0.98).
  EXPECT_LT(rms[0], 0.19) << "measured 0.159";
  EXPECT_LT(rms[1], 0.06) << "measured 0.046";
  EXPECT_LT(rms[2], 0.11) << "measured 0.091";
  // Away from the axis band (final windows reaching the ring's axis, where the exact u and w
  // jump; 752 of 159 048 vectors), within issue #7's target (0.10, 0.10, 0.50 voxel) with room.
  const sim::FieldErrors off = sim::field_errors(
      f, flow, 0.1, 1, 0, [&](const sim::Point3& x) { return !sim::in_ring_axis_band(flow, x, 0.8); });
  std::printf("off the axis band: %.3f %.3f %.3f over %zu vectors\n", off.rms[0], off.rms[1], off.rms[2], off.compared);
  EXPECT_LT(off.rms[0], 0.07) << "measured 0.056";
  EXPECT_LT(off.rms[1], 0.06) << "measured 0.045";
  EXPECT_LT(off.rms[2], 0.07) << "measured 0.049";
}

}  // namespace
}  // namespace plenopiv::piv
