// Tests: one status request to a daemon's control endpoint; nullopt while nothing answers.
#pragma once

#include <chrono>
#include <optional>
#include <string>

#include "clients/cli/control_client.hpp"
#include "plenopiv.pb.h"

namespace plenopiv::testing_support {

inline std::optional<msg::Status> probe_status(const std::string& control) {
  try {
    client::ControlClient probe(control, std::chrono::milliseconds(300));
    msg::Request r;
    r.mutable_status();
    const msg::Reply reply = probe.call(r);
    if (reply.has_status()) return reply.status();
  } catch (const client::ControlError&) {
  }
  return std::nullopt;
}

}  // namespace plenopiv::testing_support
