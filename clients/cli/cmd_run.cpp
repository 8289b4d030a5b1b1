// `plenopiv run start|stop`, `watch` and `capture-calibration`: drive runs, follow what is published.
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <fstream>
#include <iomanip>
#include <iostream>
#include <sstream>
#include <thread>
#include <zmq.hpp>

#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

#include "clients/cli/commands.hpp"
#include "clients/cli/control_client.hpp"
#include "clients/cli/png_file.hpp"
#include "core/base/errors.hpp"

namespace plenopiv::client {
namespace {

// "0.123 s", for a figure that is not always printed.
std::string seconds_text(double s) {
  std::ostringstream out;
  out << std::fixed << std::setprecision(3) << s << " s";
  return out.str();
}

msg::Reply call(const ControlOptions& options, msg::Request request) {
  ControlClient client(options.endpoint, std::chrono::milliseconds(static_cast<long>(options.timeout_s * 1000)),
                       options.security());
  msg::Reply reply = client.call(std::move(request));
  if (reply.has_error()) {
    std::cerr << "plenopivd refused: " << msg::Error::Code_Name(reply.error().code()) << ": " << reply.error().message()
              << "\n";
    throw CLI::RuntimeError(4);
  }
  return reply;
}

struct WatchOptions {
  std::string publish = "tcp://127.0.0.1:5556";
  long count = 0;
  double timeout_s = 10.0;
  bool preview = false;           // topic `preview` (the alignment preview) instead of `vectors`
  std::string png;                // with preview: write each preview here (raw frame beside the refocused slice)
  wire::ClientSecurity security;  // the control options' keys, when publishing uses CURVE
};

// One float image of a preview message as an 8-bit picture scaled to its own maximum, nearest
// neighbour up to `height` rows.
cv::Mat grey_picture(const zmq::message_t& frame, int width, int height, int rows) {
  if (width <= 0 || height <= 0 || frame.size() != std::size_t(width) * std::size_t(height) * sizeof(float)) {
    throw ControlError("a preview message whose image does not match its header's size");
  }
  const cv::Mat image(height, width, CV_32F, const_cast<void*>(frame.data()));
  double top = 0;
  cv::minMaxLoc(image, nullptr, &top);
  cv::Mat grey, big;
  image.convertTo(grey, CV_8U, top > 0 ? 255.0 / top : 0.0);
  cv::resize(grey, big, cv::Size(std::max(1, width * rows / height), rows), 0, 0, cv::INTER_NEAREST);
  return big;
}

// The raw frame (left) beside the refocused slice (right), each scaled to its own maximum.
void write_preview_png(const std::string& path, const msg::PreviewHeader& h,
                       const std::vector<zmq::message_t>& frames) {
  if (frames.size() != 3) throw ControlError("a preview message without its two images");
  const int rows = std::max(h.raw_height(), 256);
  const cv::Mat raw = grey_picture(frames[1], h.raw_width(), h.raw_height(), rows);
  const cv::Mat refocused = grey_picture(frames[2], h.refocus_width(), h.refocus_height(), rows);
  cv::Mat both;
  cv::hconcat(std::vector<cv::Mat>{raw, cv::Mat(rows, 8, CV_8U, cv::Scalar(0)), refocused}, both);
  write_png(path, both);
}

void print_preview(const msg::PreviewHeader& h) {
  std::cout << "preview pair " << std::setw(6) << h.pair_index() << "  raw " << h.raw_width() << "x" << h.raw_height()
            << " (1/" << h.downsample() << " of " << h.sensor_width_px() << "x" << h.sensor_height_px()
            << ")  counts min " << std::fixed << std::setprecision(0) << h.raw_min() << " mean " << std::setprecision(1)
            << h.raw_mean() << " max " << std::setprecision(0) << h.raw_max() << "  saturated " << std::setprecision(2)
            << 100.0 * h.saturated_fraction() << " %  refocused z " << h.refocus_z_mm() << " mm " << h.refocus_width()
            << "x" << h.refocus_height() << "  focus " << std::setprecision(6) << h.focus_measure() << "  run "
            << h.run_id() << std::endl;
}

// Subscribes to `vectors` (or `preview`) and prints one line per message; exits after `count` (0:
// never) or when nothing arrives for `timeout_s` (a clear error, exit 3).
void watch(const WatchOptions& o) {
  zmq::context_t context;
  zmq::socket_t sub(context, zmq::socket_type::sub);
  sub.set(zmq::sockopt::linger, 0);
  sub.set(zmq::sockopt::rcvtimeo, int(o.timeout_s * 1000));
  const std::string topic_name = o.preview ? "preview" : "vectors";
  sub.set(zmq::sockopt::subscribe, topic_name);
  wire::secure_client(sub, o.security);
  sub.connect(o.publish);
  for (long n = 0; o.count == 0 || n < o.count;) {
    zmq::message_t topic;
    if (!sub.recv(topic, zmq::recv_flags::none)) {
      throw ControlError(std::string(o.preview ? "no preview" : "no vector field") + " published on " + o.publish +
                         " within " + std::to_string(int(o.timeout_s)) + " s: is a run going?" +
                         (o.preview ? " Does its run.yaml ask for one (preview: {interval_s: 1})?" : "") +
                         " (plenopiv status)");
    }
    std::vector<zmq::message_t> frames;
    while (sub.get(zmq::sockopt::rcvmore)) {
      zmq::message_t frame;
      if (!sub.recv(frame, zmq::recv_flags::none)) break;
      frames.push_back(std::move(frame));
    }
    if (o.preview) {
      msg::PreviewHeader p;
      if (frames.empty() || !p.ParseFromArray(frames[0].data(), int(frames[0].size()))) {
        std::cerr << "plenopiv watch: a message on 'preview' without a header, ignored\n";
        continue;
      }
      print_preview(p);
      if (!o.png.empty()) write_preview_png(o.png, p, frames);
      ++n;
      continue;
    }
    msg::VectorFieldHeader h;
    if (frames.empty() || !h.ParseFromArray(frames[0].data(), int(frames[0].size()))) {
      std::cerr << "plenopiv watch: a message on 'vectors' without a header, ignored\n";
      continue;
    }
    std::cout << "pair " << std::setw(6) << h.pair_index() << std::fixed << std::setprecision(4) << "  mean "
              << h.mean_speed_m_s() << " m/s  max " << h.max_speed_m_s() << " m/s  valid " << std::setprecision(1)
              << 100.0 * h.valid_fraction() << " %"
              << "  latency " << std::setprecision(3) << h.latency_s() << " s"
              << (h.trigger_latency_s() > 0 ? "  from laser " + seconds_text(h.trigger_latency_s()) : std::string())
              << "  grid "
              << (h.shape_size() == 3
                      ? std::to_string(h.shape(0)) + "x" + std::to_string(h.shape(1)) + "x" + std::to_string(h.shape(2))
                      : std::string("?"))
              << "  tier " << (h.tier().empty() ? "?" : h.tier()) << "  run " << h.run_id() << std::endl;
    ++n;
  }
}

}  // namespace

void add_run_commands(CLI::App& app, ControlOptions& options) {
  auto* run = app.add_subcommand("run", "start or stop a run on plenopivd");
  run->require_subcommand(1);

  auto config = std::make_shared<std::string>();
  auto pairs = std::make_shared<unsigned>(0);
  auto* start = run->add_subcommand("start", "start a run with a run config (run.yaml)");
  start->add_option("-c,--config", *config, "run config (YAML)")->required()->check(CLI::ExistingFile);
  start->add_option("--pairs", *pairs, "number of pairs (overrides the config; 0: as configured)");
  auto no_wait = std::make_shared<bool>(false);
  start->add_flag("--no-wait", *no_wait, "answer once the daemon accepted the run, not once it acquires");
  start->callback([&options, config, pairs, no_wait] {
    std::ifstream in(*config);
    std::stringstream text;
    text << in.rdbuf();
    if (!in) throw InputError(*config + ": cannot read");
    msg::Request request;
    request.mutable_start_run()->set_config_yaml(text.str());
    request.mutable_start_run()->set_pair_count(*pairs);
    // plenopivd answers a start at once, once the quick checks pass (devices, timing, calibration,
    // disk space), and sets the run up while Armed (its weight tables: seconds at paper scale). Unless
    // --no-wait, the client then follows the setup in the daemon's status until the run acquires,
    // and says why when the setup fails.
    const msg::Reply reply = call(options, request);
    const std::string id = reply.run_started().run_id();
    std::cout << "run " << id << " started: " << reply.run_started().run_dir() << "\n" << std::flush;
    if (*no_wait) return;
    msg::Request status;
    status.mutable_status();
    std::string last;
    for (;;) {
      const msg::Status s = call(options, status).status();
      if (s.run_id() != id) return;  // another run since: this one is long past its setup
      if (s.state() == "Armed") {
        // Over the last line, cleared to its end (a shorter message leaves nothing of the longer one).
        if (s.message() != last && isatty(STDERR_FILENO)) std::cerr << "\r" << s.message() << "\033[K" << std::flush;
        last = s.message();
        std::this_thread::sleep_for(std::chrono::milliseconds(200));
        continue;
      }
      if (!last.empty() && isatty(STDERR_FILENO)) std::cerr << "\n";
      if (s.state() == "Error" && !s.run_set_up()) throw std::runtime_error(s.message());
      if (s.state() == "Error") {  // set up and acquiring, then failed: the start itself succeeded
        std::cout << "run " << id << " acquired, then failed: " << s.message() << "\n";
        return;
      }
      std::cout << "run " << id << " " << (s.state() == "Acquiring" ? "acquiring" : "state " + s.state()) << "\n";
      return;
    }
  });

  run->add_subcommand("stop", "stop the current run (in-flight pairs finish, the folder is closed)")
      ->callback([&options] {
        msg::Request request;
        request.mutable_stop_run();
        const msg::Reply reply = call(options, request);
        std::cout << "run " << reply.run_stopping().run_id() << " stopping: " << reply.run_stopping().run_dir() << "\n";
      });

  auto w = std::make_shared<WatchOptions>();
  auto* watch_cmd = app.add_subcommand("watch", "print a summary of each published vector field (or preview)");
  watch_cmd->add_option("--publish", w->publish, "plenopivd publishing endpoint")->capture_default_str();
  watch_cmd->add_option("-n,--count", w->count, "exit after this many fields (0: never)");
  watch_cmd->add_option("--wait", w->timeout_s, "seconds without a field before giving up")->capture_default_str();
  auto* preview_flag = watch_cmd->add_flag(
      "--preview", w->preview,
      "the run's alignment preview (run.yaml preview:): raw frame and refocused slice, a line each");
  watch_cmd->add_option("--png", w->png, "with --preview: write each preview to this PNG (raw | refocused)")
      ->needs(preview_flag);
  watch_cmd->callback([w, &options] {
    w->security = options.security();
    watch(*w);
  });

  auto frames = std::make_shared<unsigned>(1);
  auto camera = std::make_shared<std::string>();
  auto* cal = app.add_subcommand("capture-calibration",
                                 "take calibration images on plenopivd's camera into its data directory");
  cal->add_option("--frames", *frames, "number of images")->capture_default_str();
  cal->add_option("--camera-uri", *camera, "camera URI, e.g. aravis://Fake_1 (default: the daemon's camera_uri)");
  cal->callback([&options, frames, camera] {
    msg::Request request;
    request.mutable_calibrate()->set_frame_count(*frames);
    request.mutable_calibrate()->set_camera_uri(*camera);
    const msg::Reply reply = call(options, request);
    std::cout << reply.calibration().frame_count() << " calibration images in " << reply.calibration().dir() << "\n";
  });
}

}  // namespace plenopiv::client
