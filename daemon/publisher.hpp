// The PUB socket: status, vector fields and volumes as topic / protobuf header / float32 payloads.
#pragma once

#include <mutex>
#include <span>
#include <string>
#include <zmq.hpp>

#include <optional>

#include "core/base/grid.hpp"
#include "core/base/image.hpp"
#include "plenopiv.pb.h"
#include "proto/curve.hpp"

namespace plenopiv::daemon {

// Sends never block: with a high-water mark of a few messages per subscriber, a slow or dead
// subscriber loses messages and acquisition never waits for it. Thread safe (one lock around the
// socket, which ZeroMQ does not allow two threads to use at once).
class Publisher {
 public:
  // With `curve`, subscribers must hold a key the context's ZAP handler admits.
  Publisher(zmq::context_t& context, const std::string& endpoint, int high_water_mark,
            const std::optional<wire::CurveCertificate>& curve = std::nullopt);

  void publish_status(const msg::Status& status);
  // The grid, speeds, payload names, published time and latency (from host_timestamp_ns) are
  // filled in here.
  void publish_vectors(msg::VectorFieldHeader header, const VectorField& field);
  void publish_volume(msg::VolumeHeader header, const Volume& volume);
  // Topic `preview`: the header, then the downsampled raw frame and the refocused slice.
  void publish_preview(const msg::PreviewHeader& header, const ImageF& raw, const ImageF& refocused);
  const std::string& endpoint() const { return endpoint_; }
  std::uint64_t messages_sent() const;

 private:
  void send(const std::string& topic, const std::string& header, const std::vector<std::span<const float>>& payloads);
  mutable std::mutex mutex_;
  zmq::socket_t socket_;
  std::string endpoint_;
  std::uint64_t sent_ = 0;
};

// Mean and max speed (m/s) and the fraction of valid vectors, as published and shown by `watch`.
struct FieldSummary {
  double mean_speed_m_s = 0, max_speed_m_s = 0, valid_fraction = 0;
};
FieldSummary summarize(const VectorField& field);

}  // namespace plenopiv::daemon
