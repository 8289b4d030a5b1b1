// Tests: one status request to a daemon's control endpoint; nullopt while nothing answers.
#pragma once

#include <chrono>
#include <optional>
#include <string>

#include "clients/cli/control_client.hpp"
#include "plenopiv.pb.h"

namespace plenopiv::testing_support {

// `timeout` is short (300 ms) for polling a daemon that is starting up; a test asserting that a
// running daemon answers gives it seconds, as a sanitizer's slowdown can need.
inline std::optional<msg::Status> probe_status(const std::string& control,
                                               std::chrono::milliseconds timeout = std::chrono::milliseconds(300)) {
  try {
    client::ControlClient probe(control, timeout);
    msg::Request r;
    r.mutable_status();
    const msg::Reply reply = probe.call(r);
    if (reply.has_status()) return reply.status();
  } catch (const client::ControlError&) {
  }
  return std::nullopt;
}

}  // namespace plenopiv::testing_support
