// The live processing stage: raw pair → MART volumes A and B (core/recon) → 3D correlation (core/piv).
#pragma once

#include "core/optics/camera_model.hpp"
#include "daemon/run.hpp"

namespace plenopiv::daemon {

// For each run: the weighting operator for the run's volume (nominal microlens lattice,
// geometric white image) is built once and shared read-only by the concurrent calls; the run's
// `reconstruction` section sets MART (iterations, mu, start: mlos|ones, noise_threshold,
// dark_weight_cutoff, convergence), its `correlation` section is core/piv's correlation settings
// (passes, median, signal_threshold). dt is the laser pulse separation measured on the Q-switch
// sync input when the pair carries it, else the run's dt_s. Bad keys are InputErrors naming
// them, at run start.
ProcessFactory plenoptic_processing(const optics::CameraModel& camera);

}  // namespace plenopiv::daemon
