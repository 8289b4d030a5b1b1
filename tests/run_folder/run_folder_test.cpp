// The run folder library: what the writer puts on disk, what the reader accepts and refuses, the
// manifest's JSON, interrupted folders, and the running statistics it keeps.
#include <google/protobuf/util/json_util.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <fstream>
#include <sstream>

#include "core/base/errors.hpp"
#include "core/io/hdf5_files.hpp"
#include "core/io/tiff.hpp"
#include "proto/run_folder.hpp"
#include "proto/valid_text.hpp"
#include "tests/support/child_process.hpp"
#include "tests/support/run_manifest.hpp"
#include "tests/support/temp_dir.hpp"

namespace plenopiv::run_folder {
namespace {

namespace fs = std::filesystem;
using testing_support::read_manifest;

// Frames whose pixels tell which pair and exposure they are.
struct Frames {
  ImageU16 a, b;
  explicit Frames(std::uint64_t index) : a(8, 6, std::uint16_t(index)), b(8, 6, std::uint16_t(index + 1000)) {}
};

PairRecord record_of(std::uint64_t index, const Frames& f) {
  PairRecord r;
  r.pair_index = index;
  r.trigger_index = index;
  r.frame_a = &f.a;
  r.frame_b = &f.b;
  r.frame_id_a = 2 * index + 1;
  r.frame_id_b = 2 * index + 2;
  r.host_timestamp_a_ns = 1'000'000'000ull * (index + 1);
  r.frame_gap_s = 100e-6;
  return r;
}

// u = `u_m_s` everywhere (dt 1 ms), all valid.
VectorField field(float u_m_s) {
  Grid3 g;
  g.shape = {3, 2, 2};
  VectorField f(g);
  f.dt_s = 1e-3;
  for (std::size_t i = 0; i < g.count(); ++i) {
    f.dx_mm[i] = u_m_s;
    f.valid[i] = 1;
  }
  return f;
}

Writer::Setup setup(const fs::path& data, const std::string& id) {
  Writer::Setup s;
  s.data_dir = data;
  s.run_id = id;
  s.run_yaml = "dt_s: 0.001\n# the run config as sent\n";
  s.process_yaml = "dt_s: 0.001\n";
  s.nominal_dt_s = 1e-3;
  s.rate_hz = 10;
  s.camera_uri = "test://";
  s.trigger_uri = "sim://";
  s.camera_model = "plenopiv test camera";
  s.camera_triggering = "software: test";
  return s;
}

// manifest.json as it is on disk, without the journal.
msg::RunManifest manifest_file_alone(const fs::path& run_dir) {
  std::stringstream text;
  text << std::ifstream(run_dir / "manifest.json").rdbuf();
  return run_folder::parse_manifest(text.str(), "manifest.json");
}

TEST(RunFolder, TheWriterListsFramesVectorsStatisticsAndDropsAsTheyAreWritten) {
  const fs::path data = testing_support::temp_dir("run-folder") / "writer";
  fs::remove_all(data);
  Writer writer(setup(data, "r1"));
  EXPECT_EQ(read_manifest(writer.dir()).state(), "recording");
  for (std::uint64_t i = 0; i < 3; ++i) writer.record_pair(record_of(i, Frames(i)));
  // Vectors for pairs 0 and 2: u = 1 m/s and 3 m/s -> mean 2, RMS fluctuation 1.
  writer.record_vectors(0, field(1));
  const VectorField f3 = field(3);
  writer.record_vectors(2, f3, std::vector<std::uint8_t>(f3.grid.count(), 1));
  // The live files have the layout of `plenopiv process`: provenance, vorticity, flags when given.
  const fs::path v2 = writer.dir() / "vectors/pair-000002.h5";
  EXPECT_EQ(io::read_provenance(v2, "run"), "r1");
  EXPECT_EQ(io::read_provenance(v2, "pair_index"), "2");
  EXPECT_EQ(io::read_provenance(v2, "settings"), "dt_s: 0.001\n");
  EXPECT_EQ(io::read_provenance(v2, "dt_source"), "nominal (the run's dt_s)");
  EXPECT_EQ(io::read_provenance(v2, "frame_a").value_or("").rfind("frames/", 0), 0u);
  writer.record_drop(3, "camera queue overflow");
  writer.add_warning("frame A all zero, first in pair 1");
  writer.add_warning("frame A all zero, first in pair 1");  // listed once
  msg::RunManifest m = read_manifest(writer.dir());
  ASSERT_EQ(m.pairs_size(), 3);
  EXPECT_EQ(m.pairs(0).vectors(), "vectors/pair-000000.h5");
  EXPECT_EQ(m.pairs(1).vectors(), "");
  EXPECT_NEAR(m.pairs(1).frame_gap_s(), 100e-6, 1e-12);
  EXPECT_EQ(m.pairs(1).measured_dt_s(), 0.0);  // no laser sync measured
  msg::Losses losses;
  losses.set_camera_queue_overflow(1);
  writer.close("complete", 2, 1, losses, 2);
  writer.close("failed: twice", 0, 0);  // later calls do nothing

  m = read_manifest(writer.dir());
  EXPECT_EQ(m.state(), "complete");
  EXPECT_EQ(m.run_id(), "r1");
  EXPECT_EQ(m.config_file(), "run.yaml");
  EXPECT_EQ(m.statistics_file(), "statistics.h5");
  EXPECT_EQ(m.pairs_processed(), 2u);
  EXPECT_EQ(m.pairs_skipped(), 1u);
  EXPECT_EQ(m.frames_lost(), 2u);
  EXPECT_EQ(m.losses().camera_queue_overflow(), 1u);
  ASSERT_EQ(m.dropped_size(), 1);
  EXPECT_EQ(m.dropped(0).trigger_index(), 3u);
  EXPECT_EQ(m.dropped(0).reason(), "camera queue overflow");
  ASSERT_EQ(m.warnings_size(), 1);
  for (const msg::ManifestPair& p : m.pairs()) {
    EXPECT_EQ(io::read_tiff_u16(writer.dir() / p.frame_b()).pixels, Frames(p.pair_index()).b.pixels);
    EXPECT_EQ(p.frame_id_b(), 2 * p.pair_index() + 2);
  }
  // Mean u = 2 m/s, stored as displacement over the nominal dt (1 ms): 2 mm.
  EXPECT_NEAR(io::read_vector_field_h5(writer.dir() / "statistics.h5").dx_mm[0], 2.0, 1e-6);
  std::ifstream run_yaml(writer.dir() / "run.yaml");
  std::stringstream text;
  text << run_yaml.rdbuf();
  EXPECT_EQ(text.str(), setup(data, "r1").run_yaml);
  for (const auto& entry : fs::recursive_directory_iterator(writer.dir())) {
    EXPECT_EQ(entry.path().filename().string().find(".tmp"), std::string::npos)
        << "temporary file left: " << entry.path();
  }
}

// A recorder's row visitors see each frame's pixels once, in order, and the frames on disk are the
// frames.
TEST(RunFolder, TheRowVisitorsSeeEveryRowOfTheirFrameOnceInOrder) {
  const fs::path data = testing_support::temp_dir("run-folder") / "visitors";
  fs::remove_all(data);
  Writer writer(setup(data, "r1"));
  Frames frames(7);
  for (int y = 0; y < frames.a.height; ++y)
    for (int x = 0; x < frames.a.width; ++x) {
      frames.a.row(y)[std::size_t(x)] = std::uint16_t(100 * y + x);
      frames.b.row(y)[std::size_t(x)] = std::uint16_t(5000 + 100 * y + x);
    }
  PairRecord r = record_of(7, frames);
  HugePageVector<std::uint16_t> seen_a, seen_b;
  r.visit_rows_a = [&](std::span<const std::uint16_t> rows) { seen_a.insert(seen_a.end(), rows.begin(), rows.end()); };
  r.visit_rows_b = [&](std::span<const std::uint16_t> rows) { seen_b.insert(seen_b.end(), rows.begin(), rows.end()); };
  writer.record_pair(r);
  EXPECT_EQ(seen_a, frames.a.pixels);
  EXPECT_EQ(seen_b, frames.b.pixels);
  const ImageF on_disk = io::read_tiff_float(writer.dir() / "frames/pair-000007-B.tif");
  ASSERT_EQ(on_disk.pixels.size(), frames.b.pixels.size());
  for (std::size_t i = 0; i < on_disk.pixels.size(); ++i) EXPECT_EQ(on_disk.pixels[i], float(frames.b.pixels[i]));
}

// Integers are JSON integers (protobuf's mapping quotes 64-bit ones); strings of digits stay
// strings; and the manifest still parses with protobuf's own reader.
TEST(RunFolder, TheManifestsIntegersAreJsonIntegers) {
  msg::RunManifest m;
  m.set_run_id("20261125");  // a string of digits: stays a string
  m.set_calibration_crc32("12345678");
  m.set_calibration_bytes(3019164);
  msg::ManifestPair* p = m.add_pairs();
  p->set_pair_index(7);
  p->set_host_timestamp_a_ns(1764080000123456789ull);  // beyond 2^53: exact as an integer
  const std::string json = manifest_json(m);
  EXPECT_NE(json.find("\"pair_index\": 7"), std::string::npos) << json;
  EXPECT_NE(json.find("\"host_timestamp_a_ns\": 1764080000123456789"), std::string::npos) << json;
  EXPECT_NE(json.find("\"calibration_bytes\": 3019164"), std::string::npos) << json;
  EXPECT_NE(json.find("\"run_id\": \"20261125\""), std::string::npos) << json;
  EXPECT_NE(json.find("\"calibration_crc32\": \"12345678\""), std::string::npos) << json;
  const msg::RunManifest back = parse_manifest(json, "test");
  EXPECT_EQ(back.pairs(0).host_timestamp_a_ns(), 1764080000123456789ull);
  EXPECT_EQ(back.run_id(), "20261125");
  // Python's json reads the integers exactly (no string to convert, no float to round).
  const fs::path file = testing_support::temp_dir("run-folder") / "manifest.json";
  std::ofstream(file) << json;
  std::string out;
  ASSERT_EQ(testing_support::run_command({"/usr/bin/python3", "-c",
                                          "import json, sys; m = json.load(open(sys.argv[1])); "
                                          "print(type(m['pairs'][0]['host_timestamp_a_ns']).__name__, "
                                          "m['pairs'][0]['host_timestamp_a_ns'])",
                                          file.string()},
                                         out),
            0)
      << out;
  EXPECT_EQ(out, "int 1764080000123456789\n");
  EXPECT_THROW(parse_manifest("{\"pairs\": 3", "broken.json"), InputError);
}

// Text that is not UTF-8 (a camera's model string, a warning quoting a path or a user's bytes) is
// mended, byte by byte, to U+FFFD; well-formed text, including multi-byte characters, is kept.
TEST(ValidText, EveryMalformedByteBecomesAReplacementCharacterAndWellFormedTextIsKept) {
  const std::string replacement = "\xEF\xBF\xBD";
  for (const std::string& good :
       {std::string("plain ASCII, tab\tand newline\n"), std::string("2 \xC2\xB5m"), std::string("\xE2\x82\xAC 3"),
        std::string("\xF0\x9F\x94\xAC"), std::string("nul \0 inside", 12)}) {
    EXPECT_EQ(msg::valid_utf8(good), good);
  }
  EXPECT_EQ(msg::valid_utf8("v\"\xA0mm"), "v\"" + replacement + "mm") << "a lone continuation byte";
  EXPECT_EQ(msg::valid_utf8("\xC0\x80"), replacement + replacement) << "an overlong NUL";
  EXPECT_EQ(msg::valid_utf8("\xE0\x80\xAF"), replacement + replacement + replacement) << "an overlong slash";
  EXPECT_EQ(msg::valid_utf8("\xED\xA0\x80"), replacement + replacement + replacement) << "a surrogate";
  EXPECT_EQ(msg::valid_utf8("\xF4\x90\x80\x80"), replacement + replacement + replacement + replacement)
      << "above U+10FFFF";
  EXPECT_EQ(msg::valid_utf8("\xF5!"), replacement + "!");
  EXPECT_EQ(msg::valid_utf8("cut \xE2\x82"), "cut " + replacement + replacement) << "a sequence cut short";
  EXPECT_EQ(msg::valid_utf8("\xFF\xFE"), replacement + replacement);
}

// A manifest whose strings are not UTF-8 (nested and repeated fields too) is still written, and
// reads back with the bad bytes replaced; unmended, protobuf's JSON reader refuses it.
TEST(ValidText, AManifestWithTextThatIsNotUtf8IsWrittenAndReadsBack) {
  msg::RunManifest m;
  m.set_camera_model("Acme \xA0\xFF cam");
  m.add_warnings("frame all zero in /data/\xE9t\xE9");
  msg::ManifestDrop* drop = m.add_dropped();
  drop->set_reason("never \xC0\xAF arrived");
  std::string unmended;
  ASSERT_TRUE(google::protobuf::util::MessageToJsonString(m, &unmended, {}).ok());
  msg::RunManifest unreadable;
  EXPECT_FALSE(google::protobuf::util::JsonStringToMessage(unmended, &unreadable, {}).ok())
      << "protobuf's JSON reader took text that is not UTF-8; the mending is not needed";
  const msg::RunManifest back = parse_manifest(manifest_json(m), "test");
  EXPECT_EQ(back.camera_model(), "Acme \xEF\xBF\xBD\xEF\xBF\xBD cam");
  EXPECT_EQ(back.warnings(0), "frame all zero in /data/\xEF\xBF\xBDt\xEF\xBF\xBD");
  EXPECT_EQ(back.dropped(0).reason(), "never \xEF\xBF\xBD\xEF\xBF\xBD arrived");
  msg::RunManifest copy = m;
  EXPECT_EQ(msg::make_text_valid_utf8(copy), 3);
  EXPECT_EQ(msg::make_text_valid_utf8(copy), 0) << "mended text is left alone";
}

TEST(RunFolder, TheReaderChecksTheFolderBeforeAnythingIsProcessed) {
  const fs::path data = testing_support::temp_dir("run-folder") / "reader";
  fs::remove_all(data);
  fs::path dir;
  {
    Writer::Setup s = setup(data, "r");
    const fs::path camera = data / "camera-source.yaml";
    fs::create_directories(data);
    std::ofstream(camera) << "camera file\n";
    s.camera_file = camera;
    Writer writer(s);
    for (std::uint64_t i = 0; i < 2; ++i) {
      PairRecord r = record_of(i, Frames(i));
      if (i == 1) r.laser_pulses_ns = std::pair{std::uint64_t(1000), std::uint64_t(101000)};
      const Frames f(i);
      r.frame_a = &f.a;
      r.frame_b = &f.b;
      writer.record_pair(r);
    }
    writer.close("complete", 0, 2);
    dir = writer.dir();
  }
  const Reader reader(dir);
  ASSERT_EQ(reader.pairs().size(), 2u);
  EXPECT_EQ(reader.pairs()[0].frame_a, dir / "frames/pair-000000-A.tif");
  EXPECT_FALSE(reader.pairs()[0].measured_dt_s);
  ASSERT_TRUE(reader.pairs()[1].measured_dt_s);
  EXPECT_DOUBLE_EQ(*reader.pairs()[1].measured_dt_s, 100e-6);
  EXPECT_FALSE(reader.calibration_file());  // nominal
  EXPECT_NO_THROW(reader.check_frames(8, 6));
  try {
    reader.check_frames(10, 6);
    FAIL() << "a frame of another size was accepted";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("frame is 8 x 6"), std::string::npos) << e.what();
  }
  EXPECT_THROW(Reader(data / "no-such-run"), InputError);
}

// While a run records, manifest.json stays as the start wrote it and each pair, field, drop and
// warning goes to the journal, one line each: recording a pair costs the same at pair 10 000 as at
// pair 1. read_manifest applies the journal; a last line cut short by a crash lists nothing; any
// other bad line is named.
TEST(RunFolder, PairsGoToTheJournalWhileRecordingAndIntoTheManifestAtTheEnd) {
  const fs::path data = testing_support::temp_dir("run-folder") / "journal";
  fs::remove_all(data);
  Writer writer(setup(data, "j"));
  for (std::uint64_t i = 0; i < 4; ++i) writer.record_pair(record_of(i, Frames(i)));
  writer.record_vectors(1, field(1));
  writer.record_vectors(1, field(2), {}, process::Tier::live);
  writer.record_drop(5, "camera queue overflow");
  const fs::path journal = writer.dir() / "journal.jsonl";
  EXPECT_EQ(manifest_file_alone(writer.dir()).pairs_size(), 0);
  std::stringstream lines;
  lines << std::ifstream(journal).rdbuf();
  const std::string kept = lines.str();
  EXPECT_EQ(std::count(kept.begin(), kept.end(), '\n'), 7) << kept;
  const msg::RunManifest m = run_folder::read_manifest(writer.dir());
  ASSERT_EQ(m.pairs_size(), 4);
  EXPECT_EQ(m.pairs(3).frame_b(), "frames/pair-000003-B.tif");
  EXPECT_EQ(m.pairs(1).vectors(), "vectors/pair-000001.h5");
  EXPECT_EQ(m.pairs(1).live_vectors(), "vectors/live/pair-000001.h5");
  EXPECT_EQ(m.pairs(1).frame_a(), "frames/pair-000001-A.tif") << "a field's line keeps the pair's frames";
  ASSERT_EQ(m.dropped_size(), 1);

  // A crash while a line was being appended: the torn line lists nothing.
  std::ofstream(journal, std::ios::app) << R"({"pair": {"pair_index": 9, "frame_a": "frames/pa)";
  EXPECT_EQ(run_folder::read_manifest(writer.dir()).pairs_size(), 4);
  // A damaged line inside the journal is named.
  std::ofstream(journal, std::ios::trunc) << "{\"pair\": 3\n" << kept;
  try {
    run_folder::read_manifest(writer.dir());
    ADD_FAILURE() << "a damaged journal line was accepted";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("journal.jsonl: line 1"), std::string::npos) << e.what();
  }
  std::ofstream(journal, std::ios::trunc) << kept;

  writer.close("complete", 2, 0);
  EXPECT_FALSE(fs::exists(journal));
  const msg::RunManifest closed = manifest_file_alone(writer.dir());
  EXPECT_EQ(closed.pairs_size(), 4);
  EXPECT_EQ(closed.pairs(1).live_vectors(), "vectors/live/pair-000001.h5");
  EXPECT_EQ(closed.dropped_size(), 1);
}

// A camera lists a stray frame's loss against the trigger it infers; that trigger's pair recorded
// before or after it shows the trigger was not lost: listed once, as recorded, in the journal
// while recording and in the closed manifest.
TEST(RunFolder, ATriggerWithARecordedPairIsNeverListedDropped) {
  const fs::path data = testing_support::temp_dir("run-folder") / "reconciled";
  fs::remove_all(data);
  Writer writer(setup(data, "r"));
  writer.record_pair(record_of(0, Frames(0)));
  writer.record_drop(0, "unpaired frame");  // after its pair
  writer.record_drop(1, "unpaired frame");  // before its pair
  writer.record_drop(2, "incomplete frame");
  writer.record_pair(record_of(1, Frames(1)));
  auto dropped_triggers = [](const msg::RunManifest& m) {
    std::vector<std::uint64_t> t;
    for (const msg::ManifestDrop& d : m.dropped()) t.push_back(d.trigger_index());
    return t;
  };
  const std::vector<std::uint64_t> only_2{2};
  EXPECT_EQ(dropped_triggers(run_folder::read_manifest(writer.dir())), only_2) << "the journal, replayed";
  writer.close("complete", 0, 0);
  const msg::RunManifest closed = manifest_file_alone(writer.dir());
  EXPECT_EQ(dropped_triggers(closed), only_2);
  EXPECT_EQ(closed.pairs_size(), 2);
}

TEST(RunFolder, FoldersLeftRecordingAreMarkedInterruptedAndKeepTheirPairs) {
  const fs::path data = testing_support::temp_dir("run-folder") / "interrupted";
  fs::remove_all(data);
  {
    // A run that never closed its folder (the daemon was killed), one that did, and one damaged.
    Writer crashed(setup(data, "crashed"));
    crashed.record_pair(record_of(0, Frames(0)));
    crashed.record_pair(record_of(1, Frames(1)));
    Writer closed(setup(data, "closed"));
    closed.close("complete", 0, 0);
  }
  fs::create_directories(data / "run-damaged");
  std::ofstream(data / "run-damaged" / "manifest.json") << "{\"state\": ";
  std::vector<std::string> problems;
  const auto marked = mark_interrupted_runs(data, &problems);
  ASSERT_EQ(marked.size(), 1u);
  EXPECT_EQ(marked[0], data / "run-crashed");
  const msg::RunManifest m = read_manifest(data / "run-crashed");
  EXPECT_EQ(m.state(), "interrupted");
  EXPECT_FALSE(m.ended_utc().empty());
  EXPECT_EQ(m.pairs_size(), 2);
  // The journal was folded into manifest.json and removed.
  EXPECT_FALSE(fs::exists(data / "run-crashed" / "journal.jsonl"));
  EXPECT_EQ(manifest_file_alone(data / "run-crashed").pairs_size(), 2);
  EXPECT_EQ(read_manifest(data / "run-closed").state(), "complete");
  ASSERT_EQ(problems.size(), 1u);
  EXPECT_NE(problems[0].find("run-damaged"), std::string::npos) << problems[0];
  EXPECT_TRUE(mark_interrupted_runs(data).empty()) << "marked once";
}

TEST(RunningStatistics, WelfordMeanAndRmsOfValidVectors) {
  piv::RunningStatistics s;
  for (float d : {1.f, 3.f, 5.f}) {
    VectorField f = field(d);
    f.valid[1] = d == 5.f ? 0 : 1;  // node 1 misses the last sample
    s.add(f);
  }
  EXPECT_NEAR(s.mean(0)[0], 3.0, 1e-6);  // u = 1, 3, 5 m/s
  EXPECT_NEAR(s.rms(0)[0], std::sqrt(8.0 / 3), 1e-6);
  EXPECT_NEAR(s.mean(0)[1], 2.0, 1e-6);  // u = 1, 3
  EXPECT_NEAR(s.rms(0)[1], 1.0, 1e-6);
  EXPECT_EQ(s.count()[1], 2u);
}

}  // namespace
}  // namespace plenopiv::run_folder
