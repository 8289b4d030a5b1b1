// Setup once per geometry (core/process/operator_cache.hpp): weight tables read back from the disk
// cache are the tables built afresh (the same bits through a reconstruction); a miss writes the
// file, a hit reads it; a stale key or a damaged file is rebuilt and replaced, never trusted; an
// unwritable folder is said and the tables are built anyway; the in-process cache hands the same
// operator back and forgets the least recently used.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <string>

#include "core/calib/nominal_calibration.hpp"
#include "core/optics/camera_file.hpp"
#include "core/process/operator_cache.hpp"
#include "core/process/process.hpp"
#include "core/recon/mart.hpp"
#include "core/sim/particles.hpp"
#include "core/sim/render.hpp"
#include "tests/support/same_bits.hpp"
#include "tests/support/temp_dir.hpp"

namespace plenopiv::process {
namespace {

using testing_support::same_bits;

using Outcome = WeightsDiskCache::Outcome;

class OperatorCacheTest : public ::testing::Test {
 protected:
  void SetUp() override {
    folder_ =
        testing_support::temp_dir("operator-cache") / ::testing::UnitTest::GetInstance()->current_test_info()->name();
    std::filesystem::remove_all(folder_);
  }
  void TearDown() override { std::filesystem::remove_all(folder_); }

  static optics::CameraModel camera() {
    return optics::load_camera_file(std::string(PLENOPIV_SOURCE_DIR) + "/systemd/config/camera-small.yaml");
  }
  static Grid3 grid(double z0) { return grid_for_extent({-1, -1, z0}, {1, 1, z0 + 2}, {0.125, 0.125, 0.125}, "test"); }

  // A frame of a few ray-traced particles in the grid, reconstructed with `op`: the volume's bits.
  static HugePageVector<float> volume_through(const recon::WeightingOperator& op) {
    const optics::CameraModel cam = camera();
    const calib::LoadedCalibration nominal = calib::nominal_calibration(cam);
    const auto particles = sim::random_particles(sim::Box{{-0.8, -0.8, 0.2}, {0.8, 0.8, 1.8}}, 20, 3);
    const ImageF image = sim::render(cam, nominal.lenses, particles, sim::RenderOptions{}, 3).rays;
    recon::MartSettings s;
    s.iterations = 3;
    return recon::reconstruct(op, image, s).volume.data;
  }

  std::filesystem::path the_file() const {
    std::filesystem::path found;
    for (const auto& e : std::filesystem::directory_iterator(folder_)) found = e.path();
    return found;
  }

  std::filesystem::path folder_;
};

TEST_F(OperatorCacheTest, AMissWritesTheTablesAndAHitReadsTheSameBits) {
  const optics::CameraModel cam = camera();
  const calib::LoadedCalibration nominal = calib::nominal_calibration(cam);
  const recon::WeightingOperator built(cam, nominal.lenses, grid(0), nominal.white_correction);
  WeightsDiskCache cache(folder_);
  const auto first = cache.weights(cam, nominal.lenses, nominal.white_correction, grid(0), 1.0);
  EXPECT_EQ(cache.last_outcome(), Outcome::missing) << cache.last_note();
  ASSERT_TRUE(std::filesystem::is_regular_file(the_file())) << cache.last_note();
  EXPECT_NE(cache.last_note().find(the_file().string()), std::string::npos) << cache.last_note();
  const auto second = cache.weights(cam, nominal.lenses, nominal.white_correction, grid(0), 1.0);
  EXPECT_EQ(cache.last_outcome(), Outcome::hit) << cache.last_note();
  EXPECT_NE(cache.last_note().find("from the cache"), std::string::npos) << cache.last_note();
  // Read back: the same tables, normalisers and white image, so the same volume.
  std::string a, b;
  built.serialize(a);
  second->serialize(b);
  EXPECT_TRUE(a == b);
  EXPECT_TRUE(same_bits(volume_through(built), volume_through(*second)));
}

TEST_F(OperatorCacheTest, AnotherGeometryIsAnotherKeyAndAStaleFileIsRebuilt) {
  const optics::CameraModel cam = camera();
  const calib::LoadedCalibration nominal = calib::nominal_calibration(cam);
  const std::string key0 = operator_key(cam, nominal.lenses, nominal.white_correction, grid(0), 1.0);
  // Every input is part of the key.
  EXPECT_NE(key0, operator_key(cam, nominal.lenses, nominal.white_correction, grid(0.5), 1.0));
  EXPECT_NE(key0, operator_key(cam, nominal.lenses, nominal.white_correction, grid(0), 2.0));
  ImageF white = nominal.white_correction;
  white.pixels[12345] *= 0.5f;
  EXPECT_NE(key0, operator_key(cam, nominal.lenses, white, grid(0), 1.0));
  optics::MicrolensArray shifted = nominal.lenses;
  shifted.centres_mm[7][0] += 1e-6;
  EXPECT_NE(key0, operator_key(cam, shifted, nominal.white_correction, grid(0), 1.0));

  // The file of grid(0.5) written under grid(0)'s name: a stale file, rebuilt and replaced.
  WeightsDiskCache cache(folder_);
  cache.weights(cam, nominal.lenses, nominal.white_correction, grid(0.5), 1.0);
  const std::filesystem::path other = the_file();
  const std::filesystem::path mine = cache.file_for(key0);
  ASSERT_NE(other, mine);
  std::filesystem::rename(other, mine);
  const auto rebuilt = cache.weights(cam, nominal.lenses, nominal.white_correction, grid(0), 1.0);
  EXPECT_EQ(cache.last_outcome(), Outcome::stale) << cache.last_note();
  EXPECT_NE(cache.last_note().find("another camera, calibration, volume or settings"), std::string::npos)
      << cache.last_note();
  EXPECT_EQ(rebuilt->grid(), grid(0));
  cache.weights(cam, nominal.lenses, nominal.white_correction, grid(0), 1.0);
  EXPECT_EQ(cache.last_outcome(), Outcome::hit) << cache.last_note();
}

// A file of another format (its header's format field, after the 8-byte magic, set to the previous
// one's 1, whose checksum was a CRC-32) is stale: rebuilt, then hit.
TEST_F(OperatorCacheTest, AFileOfAnotherFormatIsStaleAndRebuilt) {
  const optics::CameraModel cam = camera();
  const calib::LoadedCalibration nominal = calib::nominal_calibration(cam);
  WeightsDiskCache cache(folder_);
  cache.weights(cam, nominal.lenses, nominal.white_correction, grid(0), 1.0);
  const std::filesystem::path file = the_file();
  {
    std::fstream f(file, std::ios::in | std::ios::out | std::ios::binary);
    const std::uint32_t previous = 1;
    f.seekp(8);
    f.write(reinterpret_cast<const char*>(&previous), sizeof previous);
  }
  cache.weights(cam, nominal.lenses, nominal.white_correction, grid(0), 1.0);
  EXPECT_EQ(cache.last_outcome(), Outcome::stale) << cache.last_note();
  EXPECT_NE(cache.last_note().find("written by another version"), std::string::npos) << cache.last_note();
  cache.weights(cam, nominal.lenses, nominal.white_correction, grid(0), 1.0);
  EXPECT_EQ(cache.last_outcome(), Outcome::hit) << cache.last_note();
}

TEST_F(OperatorCacheTest, ADamagedFileIsRebuiltNeverTrusted) {
  const optics::CameraModel cam = camera();
  const calib::LoadedCalibration nominal = calib::nominal_calibration(cam);
  const recon::WeightingOperator built(cam, nominal.lenses, grid(0), nominal.white_correction);
  std::string reference;
  built.serialize(reference);
  WeightsDiskCache cache(folder_);
  cache.weights(cam, nominal.lenses, nominal.white_correction, grid(0), 1.0);
  const std::filesystem::path file = the_file();
  const auto size = std::filesystem::file_size(file);
  const auto damage = [&](const std::string& how) {
    if (how == "flipped byte") {
      std::fstream f(file, std::ios::in | std::ios::out | std::ios::binary);
      f.seekg(std::streamoff(size - 1000));
      char c = 0;
      f.read(&c, 1);
      c = char(c ^ 0x10);
      f.seekp(std::streamoff(size - 1000));
      f.write(&c, 1);
    } else if (how == "truncated") {
      std::filesystem::resize_file(file, size / 2);
    } else if (how == "empty") {
      std::filesystem::resize_file(file, 0);
    } else {
      std::ofstream(file, std::ios::binary | std::ios::trunc) << "not a cache file at all";
    }
  };
  for (const std::string how : {"flipped byte", "truncated", "empty", "garbage"}) {
    damage(how);
    const auto op = cache.weights(cam, nominal.lenses, nominal.white_correction, grid(0), 1.0);
    EXPECT_EQ(cache.last_outcome(), Outcome::corrupt) << how << ": " << cache.last_note();
    EXPECT_NE(cache.last_note().find("replaced: corrupt"), std::string::npos) << how << ": " << cache.last_note();
    std::string bytes;
    op->serialize(bytes);
    EXPECT_TRUE(bytes == reference) << how;
    // Replaced by a sound file.
    EXPECT_EQ(std::filesystem::file_size(file), size) << how;
    cache.weights(cam, nominal.lenses, nominal.white_correction, grid(0), 1.0);
    EXPECT_EQ(cache.last_outcome(), Outcome::hit) << how << ": " << cache.last_note();
  }
}

TEST_F(OperatorCacheTest, AnUnwritableFolderIsSaidAndTheTablesAreBuilt) {
  const optics::CameraModel cam = camera();
  const calib::LoadedCalibration nominal = calib::nominal_calibration(cam);
  std::filesystem::create_directories(folder_);
  const std::filesystem::path blocked = folder_ / "a file, not a folder";
  std::ofstream(blocked) << "x";
  WeightsDiskCache cache(blocked);
  const auto op = cache.weights(cam, nominal.lenses, nominal.white_correction, grid(0), 1.0);
  ASSERT_TRUE(op);
  EXPECT_EQ(cache.last_outcome(), Outcome::unwritable) << cache.last_note();
  EXPECT_NE(cache.last_note().find("weight tables built, not kept in the cache ("), std::string::npos)
      << cache.last_note();
}

// What a get() says of its operator: the key of its inputs, and whether its tables are on disk (a
// build written there, a file read, or a kept operator that was either), whatever the note's words.
TEST_F(OperatorCacheTest, AGetSaysWhetherTheTablesAreOnDisk) {
  const optics::CameraModel cam = camera();
  const calib::LoadedCalibration nominal = calib::nominal_calibration(cam);
  const std::string key = operator_key(cam, nominal.lenses, nominal.white_correction, grid(0), 1.0);
  OperatorCache::Provenance p;
  OperatorCache written(1, folder_);
  written.get(cam, nominal.lenses, nominal.white_correction, grid(0), 1.0, &p);
  EXPECT_EQ(p.key, key);
  EXPECT_TRUE(p.on_disk) << p.note;
  written.get(cam, nominal.lenses, nominal.white_correction, grid(0), 1.0, &p);
  EXPECT_EQ(p.note, "operator kept in memory");
  EXPECT_TRUE(p.on_disk);
  OperatorCache read(1, folder_);
  read.get(cam, nominal.lenses, nominal.white_correction, grid(0), 1.0, &p);
  EXPECT_NE(p.note.find("from the cache"), std::string::npos) << p.note;
  EXPECT_TRUE(p.on_disk);

  std::filesystem::create_directories(folder_);
  const std::filesystem::path blocked = folder_ / "a file, not a folder";
  std::ofstream(blocked) << "x";
  OperatorCache unwritable(1, blocked);
  unwritable.get(cam, nominal.lenses, nominal.white_correction, grid(0), 1.0, &p);
  EXPECT_FALSE(p.on_disk) << p.note;
  unwritable.get(cam, nominal.lenses, nominal.white_correction, grid(0), 1.0, &p);
  EXPECT_EQ(p.note, "operator kept in memory");
  EXPECT_FALSE(p.on_disk);
  OperatorCache memory_only(1);
  memory_only.get(cam, nominal.lenses, nominal.white_correction, grid(0), 1.0, &p);
  EXPECT_EQ(p.note, "operator built");
  EXPECT_EQ(p.key, key);
  EXPECT_FALSE(p.on_disk);
}

TEST_F(OperatorCacheTest, TheFolderKeepsTheMostRecentlyUsedFiles) {
  const optics::CameraModel cam = camera();
  const calib::LoadedCalibration nominal = calib::nominal_calibration(cam);
  WeightsDiskCache cache(folder_, 2);
  for (const double z0 : {0.0, 0.5, 1.0}) cache.weights(cam, nominal.lenses, nominal.white_correction, grid(z0), 1.0);
  std::size_t files = 0;
  for ([[maybe_unused]] const auto& e : std::filesystem::directory_iterator(folder_)) ++files;
  EXPECT_EQ(files, 2u);
  EXPECT_TRUE(std::filesystem::exists(
      cache.file_for(operator_key(cam, nominal.lenses, nominal.white_correction, grid(1.0), 1.0))));
}

TEST_F(OperatorCacheTest, TheInProcessCacheHandsBackTheSameOperator) {
  const optics::CameraModel cam = camera();
  const calib::LoadedCalibration nominal = calib::nominal_calibration(cam);
  OperatorCache cache(2);
  const auto a = cache.get(cam, nominal.lenses, nominal.white_correction, grid(0), 1.0);
  const auto again = cache.get(cam, nominal.lenses, nominal.white_correction, grid(0), 1.0);
  EXPECT_EQ(a.get(), again.get());
  EXPECT_EQ(cache.last_note(), "operator kept in memory");
  const auto b = cache.get(cam, nominal.lenses, nominal.white_correction, grid(0.5), 1.0);
  const auto c = cache.get(cam, nominal.lenses, nominal.white_correction, grid(1.0), 1.0);
  EXPECT_NE(b.get(), a.get());
  EXPECT_EQ(cache.counts().hits, 1u);
  EXPECT_EQ(cache.counts().builds, 3u);
  // Capacity 2: the first was forgotten, the last two kept.
  EXPECT_NE(cache.get(cam, nominal.lenses, nominal.white_correction, grid(0), 1.0).get(), a.get());
  EXPECT_EQ(cache.get(cam, nominal.lenses, nominal.white_correction, grid(1.0), 1.0).get(), c.get());
  EXPECT_TRUE(
      same_bits(volume_through(a->weights()),
                volume_through(cache.get(cam, nominal.lenses, nominal.white_correction, grid(0), 1.0)->weights())));
}

}  // namespace
}  // namespace plenopiv::process
