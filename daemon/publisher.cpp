// The PUB socket: status, vector fields and volumes as topic / protobuf header / float32 payloads.
#include "daemon/publisher.hpp"

#include <bit>
#include <chrono>
#include <cmath>

#include "core/base/errors.hpp"
#include "proto/valid_text.hpp"

namespace plenopiv::daemon {

static_assert(std::endian::native == std::endian::little,
              "payloads are sent as the machine's float32: little-endian hosts only");

Publisher::Publisher(zmq::context_t& context, const std::string& endpoint, int high_water_mark,
                     const std::optional<wire::CurveCertificate>& curve)
    : socket_(context, zmq::socket_type::pub), endpoint_(endpoint) {
  socket_.set(zmq::sockopt::sndhwm, high_water_mark);
  socket_.set(zmq::sockopt::linger, 0);
  if (curve) wire::secure_server(socket_, *curve, "plenopiv-publish");
  try {
    socket_.bind(endpoint);
  } catch (const zmq::error_t& e) {
    throw InputError("publish endpoint " + endpoint + ": cannot bind: " + e.what());
  }
  endpoint_ = socket_.get(zmq::sockopt::last_endpoint);
}

void Publisher::send(const std::string& topic, const std::string& header,
                     const std::vector<std::span<const float>>& payloads) {
  std::lock_guard lock(mutex_);
  // A PUB socket never blocks: at the high-water mark it drops the whole message for that
  // subscriber (multipart messages are delivered whole or not at all).
  socket_.send(zmq::buffer(topic), zmq::send_flags::sndmore | zmq::send_flags::dontwait);
  socket_.send(zmq::buffer(header),
               (payloads.empty() ? zmq::send_flags::none : zmq::send_flags::sndmore) | zmq::send_flags::dontwait);
  for (std::size_t i = 0; i < payloads.size(); ++i) {
    socket_.send(
        zmq::buffer(payloads[i].data(), payloads[i].size_bytes()),
        (i + 1 < payloads.size() ? zmq::send_flags::sndmore : zmq::send_flags::none) | zmq::send_flags::dontwait);
  }
  ++sent_;
}

std::uint64_t Publisher::messages_sent() const {
  std::lock_guard lock(mutex_);
  return sent_;
}

void Publisher::publish_status(const msg::Status& status) {
  msg::Status valid = status;
  msg::make_text_valid_utf8(valid);
  send("status", valid.SerializeAsString(), {});
}

FieldSummary summarize(const VectorField& field) {
  FieldSummary s;
  std::size_t valid = 0;
  double sum = 0;
  const double to_m_s = field.dt_s > 0 ? 1e-3 / field.dt_s : 0.0;
  for (std::size_t i = 0; i < field.valid.size(); ++i) {
    if (!field.valid[i]) continue;
    const double speed = std::sqrt(double(field.dx_mm[i]) * field.dx_mm[i] + double(field.dy_mm[i]) * field.dy_mm[i] +
                                   double(field.dz_mm[i]) * field.dz_mm[i]) *
                         to_m_s;
    ++valid;
    sum += speed;
    s.max_speed_m_s = std::max(s.max_speed_m_s, speed);
  }
  s.mean_speed_m_s = valid ? sum / double(valid) : 0.0;
  s.valid_fraction = field.valid.empty() ? 0.0 : double(valid) / double(field.valid.size());
  return s;
}

void Publisher::publish_vectors(msg::VectorFieldHeader header, const VectorField& field) {
  const Grid3& g = field.grid;
  header.clear_shape();
  header.clear_origin_mm();
  header.clear_spacing_mm();
  header.clear_payloads();
  for (int a = 0; a < 3; ++a) {
    header.add_shape(g.shape[a]);
    header.add_origin_mm(g.origin_mm[a]);
    header.add_spacing_mm(g.spacing_mm[a]);
  }
  header.set_dt_s(field.dt_s);
  const FieldSummary s = summarize(field);
  header.set_mean_speed_m_s(s.mean_speed_m_s);
  header.set_max_speed_m_s(s.max_speed_m_s);
  header.set_valid_fraction(s.valid_fraction);
  const double to_m_s = field.dt_s > 0 ? 1e-3 / field.dt_s : 0.0;
  // With the uncertainty: sigma_u, sigma_v, sigma_w after the others.
  const bool sigma = field.has_sigma();
  std::vector<std::vector<float>> payloads(sigma ? 7 : 4, std::vector<float>(g.count()));
  for (std::size_t i = 0; i < g.count(); ++i) {
    payloads[0][i] = float(field.dx_mm[i] * to_m_s);
    payloads[1][i] = float(field.dy_mm[i] * to_m_s);
    payloads[2][i] = float(field.dz_mm[i] * to_m_s);
    payloads[3][i] = field.valid[i] ? 1.f : 0.f;
    if (!sigma) continue;
    payloads[4][i] = float(field.sigma_dx_mm[i] * to_m_s);
    payloads[5][i] = float(field.sigma_dy_mm[i] * to_m_s);
    payloads[6][i] = float(field.sigma_dz_mm[i] * to_m_s);
  }
  for (const char* name : {"u", "v", "w", "valid"}) header.add_payloads(name);
  if (sigma) {
    for (const char* name : {"sigma_u", "sigma_v", "sigma_w"}) header.add_payloads(name);
    header.set_sigma_method(field.sigma_method);
  }
  const auto now_ns = std::uint64_t(
      std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::system_clock::now().time_since_epoch())
          .count());
  header.set_published_ns(now_ns);
  if (header.host_timestamp_ns() != 0) {
    header.set_latency_s((double(now_ns) - double(header.host_timestamp_ns())) * 1e-9);
  }
  send("vectors", header.SerializeAsString(), {payloads.begin(), payloads.end()});
}

void Publisher::publish_volume(msg::VolumeHeader header, const Volume& volume) {
  header.clear_shape();
  header.clear_origin_mm();
  header.clear_spacing_mm();
  for (int a = 0; a < 3; ++a) {
    header.add_shape(volume.grid.shape[a]);
    header.add_origin_mm(volume.grid.origin_mm[a]);
    header.add_spacing_mm(volume.grid.spacing_mm[a]);
  }
  send("volume", header.SerializeAsString(), {volume.data});
}

void Publisher::publish_preview(const msg::PreviewHeader& header, const ImageF& raw, const ImageF& refocused) {
  send("preview", header.SerializeAsString(), {raw.pixels, refocused.pixels});
}

}  // namespace plenopiv::daemon
