// The live processing stage: raw pair → process::process_pair (MART of A and B, 3D correlation).
#pragma once

#include "core/optics/camera_model.hpp"
#include "daemon/run.hpp"

namespace plenopiv::daemon {

// For each run: the settings are core/process's, read from RunConfig::process_yaml() (the run's
// volume, `reconstruction`: MART iterations, mu, acceleration: none|nesterov, start: mlos|ones,
// noise_threshold, dark_weight_cutoff, convergence, angular_sampling, sensor_blur_sigma_mm;
// `correlation`: core/piv's passes, median, signal_threshold);
// the pair operator for the run's volume (process::PairOperator: the run's calibration's lens
// centres and white correction, or the nominal lattice and geometric white image without one;
// its note, e.g. resampling a rotated array, goes to the log) is built once and shared read-only
// by the concurrent calls to process::process_pair; MART's buffers (recon::MartWorkspace) are kept
// from pair to pair, one per pair in flight. dt is the
// laser pulse separation measured on the Q-switch sync input when the pair carries it, else the
// run's dt_s. Bad keys are InputErrors naming them, at run start.
ProcessFactory plenoptic_processing(const optics::CameraModel& camera);

}  // namespace plenopiv::daemon
