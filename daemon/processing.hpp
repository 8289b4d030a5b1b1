// The live processing stage: a thin adapter from recorded pairs to process::PairProcessor.
#pragma once

#include <filesystem>
#include <string>

#include "core/optics/camera_model.hpp"
#include "core/process/process.hpp"
#include "daemon/run.hpp"

namespace plenopiv::daemon {

// For each lane of a run: a process::PairProcessor from the settings of the lane's tier in the
// run's processing spec (RunConfig::spec, the keys core/process reads: docs/daemon.md) and the run's
// calibration (or the nominal calibration), built once and shared by the lane's concurrent pairs,
// whose buffers it reserves at once (PairProcessor::reserve_workspaces: the run is Armed); each pair goes through it
// with its measured dt and the run's cancel flag. A run whose pairs in flight (both lanes) would not fit this machine's
// memory, or whose settings do not fit the camera, is refused (InputError) before the run folder exists. The factory
// keeps the operators (weight tables) of its latest runs (process::OperatorCache, in memory): a run on the camera,
// calibration and volume of an earlier one builds no tables. A tier with a depth response
// (reconstruction.depth_response_ppm) keeps it in `response_folder` (process::DepthResponseDiskCache;
// empty: not kept), where a later run with the same inputs and settings reads it back. The live
// lane's is measured while the run is Armed, saying how far it is through the factory's progress
// (where a stopped run ends it); the quality lane's by its first pair, while the run acquires.
ProcessFactory plenoptic_processing(const optics::CameraModel& camera,
                                    const std::filesystem::path& response_folder = {});

// What the quality lane's status says while its first pair measures `tier`'s depth response: the
// fraction measured (0..1), the seconds it has taken so far and, once under way, about how long
// the rest takes at that pace (minutes at the paper's scale).
std::string depth_response_activity(process::Tier tier, double fraction, double elapsed_s);

}  // namespace plenopiv::daemon
