// `aravis://<device-id or address>`: GenICam cameras (GigE Vision, USB3 Vision) through Aravis 0.8.
#include "drivers/camera/aravis/aravis_camera.hpp"

#include <arv.h>

#include <atomic>
#include <condition_variable>
#include <cstring>
#include <deque>
#include <functional>
#include <future>
#include <mutex>
#include <thread>

#include "core/base/errors.hpp"
#include "drivers/camera/aravis/camera_profile.hpp"
#include "drivers/camera/camera_base.hpp"
#include "drivers/common/driver_errors.hpp"

namespace plenopiv::drivers {
namespace {

// Takes ownership of a GError and returns its message ("" if none).
std::string take_error(GError*& error) {
  if (!error) return {};
  std::string message = error->message ? error->message : "unknown error";
  g_clear_error(&error);
  return message;
}

std::string or_empty(const char* s) { return s ? s : ""; }

// Aravis is not thread-safe: every call on the camera, device and stream below happens on one
// control thread. The stream's own thread only pops finished buffers and queues them
// (on_new_buffer); the heartbeat thread only raises a flag (on_control_lost).
class AravisCamera final : public CameraBase {
 public:
  AravisCamera(const DeviceUri& uri)
      : CameraBase(CameraInfo{uri.text(), {}, {}, {}, 0, 0, {}}),
        uri_(uri),
        profile_(find_camera_profile(uri.string_or("profile", "sfnc-burst"))) {
    uri.reject_unknown({"profile", "packet_size", "socket_buffer", "buffers", "resend", "reconnect_s"});
    if (uri.target().empty()) uri.fail("needs a device id or address, e.g. aravis://127.0.0.1");
    packet_size_ = int(uri.integer_or("packet_size", 0));
    if (packet_size_ < 0 || packet_size_ > 65000) uri.fail("packet_size must be within 0..65000");
    socket_buffer_ = uri.integer_or("socket_buffer", 0);
    if (socket_buffer_ < 0) uri.fail("socket_buffer must be >= 0");
    n_buffers_ = int(uri.integer_or("buffers", 16));
    if (n_buffers_ < 4 || n_buffers_ > 1024) uri.fail("buffers must be within 4..1024");
    const std::string resend = uri.string_or("resend", "on");
    if (resend != "on" && resend != "off") uri.fail("resend must be on or off, got '" + resend + "'");
    resend_ = resend == "on";
    reconnect_interval_ = std::chrono::duration<double>(uri.number_or("reconnect_s", 1.0));
    if (reconnect_interval_.count() <= 0) uri.fail("reconnect_s must be > 0");

    PairerOptions pairing;
    pairing.max_gap_ns = std::uint64_t(profile_.max_pair_gap_s * 1e9);
    pairing.frame_id_modulus = profile_.frame_id_bits == 16 ? 65536 : 0;
    set_pairing(pairing);
    thread_ = std::thread([this] { control_loop(); });
  }

  ~AravisCamera() override {
    try {
      run([this] { disconnect(true); });
    } catch (...) {
      // Closing a camera that is already gone: nothing left to do.
    }
    {
      std::lock_guard lock(mutex_);
      quit_ = true;
    }
    wake_.notify_all();
    thread_.join();
  }

  void open() {
    run([this] {
      connect();
      // The first open fails loudly; later reconnects retry instead.
      CameraInfo info = this->info();
      info.vendor = vendor_;
      info.model = model_;
      info.serial = serial_;
      info.sensor_width_px = sensor_w_;
      info.sensor_height_px = sensor_h_;
      info.double_exposure = profile_.mode + " (profile " + profile_.name + ")";
      set_info(info);
    });
  }

 protected:
  void do_configure(const CameraSettings& settings) override {
    run([&] {
      apply_settings(settings);
      settings_ = settings;
    });
  }
  void do_arm(const DoubleExposureSettings& settings) override {
    run([&] {
      apply_double_exposure(settings);
      armed_ = settings;
    });
  }
  void do_start() override {
    run([&] {
      if (!settings_) apply_settings(CameraSettings{});
      start_stream();
    });
  }
  void do_stop() override {
    run([&] { stop_stream(true); });
  }
  void do_software_trigger() override {
    if (!armed_ || armed_->trigger != TriggerSource::Software) {
      throw StateError("camera " + uri_.text() +
                       ": software_trigger needs arm() with "
                       "TriggerSource::Software");
    }
    run([&] { fire_software_trigger(); });
  }
  std::uint64_t packets_resent() const override { return resent_base_ + resent_now_; }

 private:
  // Runs `f` on the control thread and waits; its exception comes back to the caller.
  void run(std::function<void()> f) {
    auto task = std::make_shared<std::packaged_task<void()>>(std::move(f));
    std::future<void> done = task->get_future();
    {
      std::lock_guard lock(mutex_);
      commands_.push_back([task] { (*task)(); });
    }
    wake_.notify_all();
    done.get();
  }

  // Aravis's stream thread (C): nothing may throw through it. A buffer that cannot be queued goes
  // back to the stream (its frame is then counted lost by the pairer's id gap).
  static void on_new_buffer(ArvStream* stream, gpointer self_ptr) {
    auto* self = static_cast<AravisCamera*>(self_ptr);
    ArvBuffer* buffer = arv_stream_try_pop_buffer(stream);
    if (!buffer) return;
    try {
      std::lock_guard lock(self->mutex_);
      self->buffers_.push_back(buffer);
    } catch (...) {
      arv_stream_push_buffer(stream, buffer);
      return;
    }
    self->wake_.notify_all();
  }

  static void on_control_lost(ArvDevice*, gpointer self_ptr) {
    auto* self = static_cast<AravisCamera*>(self_ptr);
    self->control_lost_ = true;
    self->wake_.notify_all();
  }

  void control_loop() {
    auto last_stats = std::chrono::steady_clock::now();
    while (true) {
      std::deque<std::function<void()>> commands;
      std::deque<ArvBuffer*> buffers;
      {
        std::unique_lock lock(mutex_);
        wake_.wait_for(lock, std::chrono::milliseconds(50),
                       [this] { return quit_ || !commands_.empty() || !buffers_.empty() || control_lost_; });
        if (quit_) break;
        commands.swap(commands_);
        buffers.swap(buffers_);
      }
      // This thread never dies silently: a failure here fails the camera with its reason (a run
      // using it then fails), and the loop keeps serving commands such as stop.
      try {
        for (ArvBuffer* b : buffers) take_buffer(b);
        for (auto& c : commands) c();
        if (control_lost_ && camera_) handle_loss("control lost: the camera stopped answering");
        if (!camera_ && lost_ && std::chrono::steady_clock::now() >= next_retry_) try_reconnect();
        if (std::chrono::steady_clock::now() - last_stats > std::chrono::milliseconds(200)) {
          update_statistics();
          last_stats = std::chrono::steady_clock::now();
        }
      } catch (const std::exception& e) {
        report_failed(std::string("camera driver thread: ") + e.what());
      }
    }
  }

  // Control thread: turns a finished buffer into a Frame and gives the buffer back to the stream.
  void take_buffer(ArvBuffer* buffer) {
    Frame frame;
    frame.frame_id = arv_buffer_get_frame_id(buffer);
    frame.device_timestamp_ns = arv_buffer_get_timestamp(buffer);
    frame.host_timestamp_ns = arv_buffer_get_system_timestamp(buffer);
    const ArvBufferStatus status = arv_buffer_get_status(buffer);
    frame.complete = status == ARV_BUFFER_STATUS_SUCCESS;
    if (frame.complete) {
      const ArvPixelFormat format = arv_buffer_get_image_pixel_format(buffer);
      const int w = arv_buffer_get_image_width(buffer);
      const int h = arv_buffer_get_image_height(buffer);
      size_t size = 0;
      const void* data = arv_buffer_get_image_data(buffer, &size);
      const std::size_t n = std::size_t(w) * std::size_t(h);
      if (format == ARV_PIXEL_FORMAT_MONO_8 && data && size >= n) {
        frame.image = frame_buffers().take(w, h);
        frame.bit_depth = 8;
        const auto* src = static_cast<const std::uint8_t*>(data);
        for (std::size_t i = 0; i < n; ++i) frame.image.pixels[i] = src[i];
      } else if ((format == ARV_PIXEL_FORMAT_MONO_16 || format == ARV_PIXEL_FORMAT_MONO_12) && data && size >= 2 * n) {
        frame.image = frame_buffers().take(w, h);
        frame.bit_depth = format == ARV_PIXEL_FORMAT_MONO_12 ? 12 : 16;
        std::memcpy(frame.image.pixels.data(), data, 2 * n);
      } else {
        // A format we did not ask for, or less data than the header claims: not a usable frame.
        frame.complete = false;
      }
    }
    if (stream_ && buffer_owner_ == stream_) {
      arv_stream_push_buffer(stream_, buffer);
    } else {
      g_object_unref(buffer);
    }
    ++buffers_taken_;
    submit_frame(std::move(frame));
  }

  void connect() {
    GError* error = nullptr;
    ArvCamera* camera = arv_camera_new(uri_.target().c_str(), &error);
    if (!camera) {
      uri_.fail("camera '" + uri_.target() + "' not found: " + take_error(error));
    }
    camera_ = camera;
    vendor_ = or_empty(arv_camera_get_vendor_name(camera_, nullptr));
    model_ = or_empty(arv_camera_get_model_name(camera_, nullptr));
    serial_ = or_empty(arv_camera_get_device_serial_number(camera_, nullptr));
    arv_camera_get_sensor_size(camera_, &sensor_w_, &sensor_h_, nullptr);
    ArvDevice* device = arv_camera_get_device(camera_);
    check_camera_profile(
        profile_, [device](const std::string& name) { return probe_feature(device, name); },
        uri_.text() + " (" + vendor_ + " " + model_ + ")");
    if (packet_size_ > 0 && arv_camera_is_gv_device(camera_)) {
      arv_camera_gv_set_packet_size(camera_, packet_size_, &error);
      if (error) uri_.fail("packet_size " + std::to_string(packet_size_) + ": " + take_error(error));
    }
    control_lost_ = false;
    g_signal_connect(device, "control-lost", G_CALLBACK(on_control_lost), this);
  }

  static std::optional<std::vector<std::string>> probe_feature(ArvDevice* device, const std::string& name) {
    ArvGcNode* node = arv_device_get_feature(device, name.c_str());
    if (!node) return std::nullopt;
    std::vector<std::string> values;
    if (ARV_IS_GC_ENUMERATION(node)) {
      guint n = 0;
      GError* error = nullptr;
      const char** entries =
          arv_device_dup_available_enumeration_feature_values_as_strings(device, name.c_str(), &n, &error);
      take_error(error);
      for (guint i = 0; entries && i < n; ++i) values.push_back(entries[i]);
      g_free(entries);
      if (values.empty()) return std::nullopt;  // an enumeration with no usable value
    }
    return values;
  }

  // Control thread: releases the stream and the camera. `orderly`: the camera still answers.
  void disconnect(bool orderly) {
    stop_stream(orderly);
    if (camera_) {
      g_signal_handlers_disconnect_by_data(arv_camera_get_device(camera_), this);
      g_object_unref(camera_);
      camera_ = nullptr;
    }
  }

  void apply_settings(const CameraSettings& s) {
    GError* error = nullptr;
    const int w = s.roi.width > 0 ? s.roi.width : sensor_w_ - s.roi.x;
    const int h = s.roi.height > 0 ? s.roi.height : sensor_h_ - s.roi.y;
    arv_camera_set_region(camera_, s.roi.x, s.roi.y, w, h, &error);
    if (error) fail_setting("roi", take_error(error));
    guint n = 0;
    const char** formats = arv_camera_dup_available_pixel_formats_as_strings(camera_, &n, nullptr);
    bool offered = false;
    std::string list;
    for (guint i = 0; formats && i < n; ++i) {
      offered = offered || std::strcmp(formats[i], to_string(s.pixel_format)) == 0;
      list += (list.empty() ? "" : ", ") + std::string(formats[i]);
    }
    g_free(formats);
    if (!offered) {
      fail_setting("pixel_format",
                   std::string(to_string(s.pixel_format)) + " is not offered (the camera has: " + list + ")");
    }
    arv_camera_set_pixel_format_from_string(camera_, to_string(s.pixel_format), &error);
    if (error) fail_setting("pixel_format", take_error(error));
    arv_camera_set_exposure_time(camera_, s.exposure_s * 1e6, &error);
    if (error) fail_setting("exposure_s", take_error(error));
    if (arv_camera_is_gain_available(camera_, nullptr)) {
      arv_camera_set_gain(camera_, s.gain_db, &error);
      if (error) fail_setting("gain_db", take_error(error));
    } else if (s.gain_db != 0) {
      fail_setting("gain_db", "the camera has no gain control");
    }
  }

  [[noreturn]] void fail_setting(const std::string& key, const std::string& reason) const {
    throw InputError("camera " + uri_.text() + ": " + key + ": " + reason);
  }

  void set_feature(const FeatureSetting& s) {
    ArvGcNode* node = arv_device_get_feature(arv_camera_get_device(camera_), s.feature.c_str());
    if (!node || !ARV_IS_GC_FEATURE_NODE(node)) {
      throw InputError("camera " + uri_.text() + ": profile " + profile_.name + ": feature " + s.feature +
                       " is missing");
    }
    GError* error = nullptr;
    arv_gc_feature_node_set_value_from_string(ARV_GC_FEATURE_NODE(node), s.value.c_str(), &error);
    if (error) {
      throw InputError("camera " + uri_.text() + ": profile " + profile_.name + ": " + s.feature + "=" + s.value +
                       ": " + take_error(error));
    }
  }

  void apply_double_exposure(const DoubleExposureSettings& s) {
    for (const FeatureSetting& f : profile_.features) set_feature(f);
    const auto& trigger = s.trigger == TriggerSource::Software ? profile_.software_trigger : profile_.external_trigger;
    for (const FeatureSetting& f : trigger) set_feature(f);
    if (s.max_pair_gap_s > 0) {
      PairerOptions pairing;
      pairing.max_gap_ns = std::uint64_t(s.max_pair_gap_s * 1e9);
      pairing.frame_id_modulus = profile_.frame_id_bits == 16 ? 65536 : 0;
      set_pairing(pairing);
    }
  }

  void start_stream() {
    GError* error = nullptr;
    ArvStream* stream = arv_camera_create_stream(camera_, nullptr, nullptr, &error);
    if (!stream) throw DeviceError("camera " + uri_.text() + ": no stream: " + take_error(error));
    if (ARV_IS_GV_STREAM(stream)) {
      if (socket_buffer_ > 0) {
        g_object_set(stream, "socket-buffer", ARV_GV_STREAM_SOCKET_BUFFER_FIXED, "socket-buffer-size",
                     gint(socket_buffer_), nullptr);
      }
      g_object_set(stream, "packet-resend",
                   resend_ ? ARV_GV_STREAM_PACKET_RESEND_ALWAYS : ARV_GV_STREAM_PACKET_RESEND_NEVER, nullptr);
    }
    const guint payload = arv_camera_get_payload(camera_, &error);
    if (error) {
      g_object_unref(stream);
      throw DeviceError("camera " + uri_.text() + ": payload size: " + take_error(error));
    }
    for (int i = 0; i < n_buffers_; ++i) arv_stream_push_buffer(stream, arv_buffer_new(payload, nullptr));
    stream_ = stream;
    buffer_owner_ = stream;
    g_signal_connect(stream_, "new-buffer", G_CALLBACK(on_new_buffer), this);
    arv_stream_set_emit_signals(stream_, TRUE);
    arv_camera_start_acquisition(camera_, &error);
    if (error) {
      const std::string message = take_error(error);
      stop_stream(false);
      throw DeviceError("camera " + uri_.text() + ": start acquisition: " + message);
    }
  }

  void stop_stream(bool orderly) {
    if (!stream_) return;
    if (orderly && camera_) {
      GError* error = nullptr;
      arv_camera_stop_acquisition(camera_, &error);
      take_error(error);  // the stream goes either way
    }
    arv_stream_set_emit_signals(stream_, FALSE);
    g_signal_handlers_disconnect_by_data(stream_, this);
    update_statistics();
    resent_base_ += resent_now_;
    resent_now_ = 0;
    ArvStream* stream = stream_;
    stream_ = nullptr;
    g_object_unref(stream);  // joins the stream thread; the stream frees the buffers it holds
    // Buffers popped before the stream went: deliver their frames, then free them.
    std::deque<ArvBuffer*> left;
    {
      std::lock_guard lock(mutex_);
      left.swap(buffers_);
    }
    for (ArvBuffer* b : left) take_buffer(b);
    buffer_owner_ = nullptr;
  }

  void fire_software_trigger() {
    if (!camera_) throw DeviceError("camera " + uri_.text() + " is lost");
    ArvDevice* device = arv_camera_get_device(camera_);
    const auto period = std::chrono::duration_cast<std::chrono::steady_clock::duration>(
        std::chrono::duration<double>(profile_.min_pair_period_s));
    std::this_thread::sleep_until(last_trigger_ + period);
    last_trigger_ = std::chrono::steady_clock::now();
    for (int i = 0; i < profile_.software_trigger_repeat; ++i) {
      if (i > 0) {
        // A camera that latches one software trigger at a time would merge two commands sent
        // too close together: wait for frame A (or half a second) before asking for frame B.
        std::this_thread::sleep_for(std::chrono::duration<double>(profile_.software_trigger_spacing_s));
        wait_for_buffer(std::chrono::milliseconds(500));
      }
      buffers_seen_at_trigger_ = buffers_taken_;
      GError* error = nullptr;
      arv_device_execute_command(device, profile_.software_trigger_command.c_str(), &error);
      if (error) {
        // A command the camera does not answer: it is gone (power, cable), found now rather than
        // by the heartbeat seconds later; the control loop reconnects.
        const bool timeout = (error->domain == ARV_DEVICE_ERROR && error->code == ARV_DEVICE_ERROR_TIMEOUT) ||
                             (error->message && std::strstr(error->message, "timeout"));
        const std::string message = profile_.software_trigger_command + ": " + take_error(error);
        if (timeout) handle_loss("control lost: " + message);
        throw DeviceError("camera " + uri_.text() + ": " + message);
      }
    }
  }

  // Control thread: takes finished buffers until one arrives after the last trigger, or timeout.
  void wait_for_buffer(std::chrono::milliseconds timeout) {
    const auto deadline = std::chrono::steady_clock::now() + timeout;
    while (buffers_taken_ == buffers_seen_at_trigger_) {
      std::deque<ArvBuffer*> buffers;
      {
        std::unique_lock lock(mutex_);
        if (!wake_.wait_until(lock, deadline, [this] { return !buffers_.empty(); })) return;
        buffers.swap(buffers_);
      }
      for (ArvBuffer* b : buffers) take_buffer(b);
    }
  }

  void update_statistics() {
    if (!stream_ || !ARV_IS_GV_STREAM(stream_)) return;
    guint64 resent = 0, missing = 0;
    arv_gv_stream_get_statistics(ARV_GV_STREAM(stream_), &resent, &missing);
    resent_now_ = resent;
  }

  void handle_loss(const std::string& reason) {
    report_lost(reason);
    lost_ = true;
    disconnect(false);
    next_retry_ = std::chrono::steady_clock::now();
  }

  void try_reconnect() {
    next_retry_ = std::chrono::steady_clock::now() +
                  std::chrono::duration_cast<std::chrono::steady_clock::duration>(reconnect_interval_);
    try {
      connect();
      if (settings_) apply_settings(*settings_);
      if (armed_) apply_double_exposure(*armed_);
      if (wanted_state() == CameraState::Running) start_stream();
      lost_ = false;
      report_reconnected();
    } catch (const std::exception& e) {
      disconnect(false);
      report_lost("control lost; reconnecting: " + std::string(e.what()));
    }
  }

  DeviceUri uri_;
  CameraProfile profile_;
  int packet_size_ = 0;
  long long socket_buffer_ = 0;
  int n_buffers_ = 16;
  bool resend_ = true;
  std::chrono::duration<double> reconnect_interval_{1.0};

  std::thread thread_;
  std::mutex mutex_;  // guards commands_, buffers_, quit_
  std::condition_variable wake_;
  std::deque<std::function<void()>> commands_;
  std::deque<ArvBuffer*> buffers_;
  bool quit_ = false;
  std::atomic<bool> control_lost_{false};
  std::atomic<std::uint64_t> resent_base_{0}, resent_now_{0};

  // Control thread only.
  ArvCamera* camera_ = nullptr;
  ArvStream* stream_ = nullptr;
  ArvStream* buffer_owner_ = nullptr;
  std::string vendor_, model_, serial_;
  int sensor_w_ = 0, sensor_h_ = 0;
  std::optional<CameraSettings> settings_;
  std::optional<DoubleExposureSettings> armed_;
  bool lost_ = false;
  std::chrono::steady_clock::time_point next_retry_;
  std::chrono::steady_clock::time_point last_trigger_;
  std::uint64_t buffers_taken_ = 0;
  std::uint64_t buffers_seen_at_trigger_ = 0;
};

}  // namespace

std::unique_ptr<Camera> open_aravis_camera(const DeviceUri& uri) {
  auto camera = std::make_unique<AravisCamera>(uri);
  camera->open();
  return camera;
}

}  // namespace plenopiv::drivers
