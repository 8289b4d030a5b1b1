// File formats: TIFF, HDF5 and VTI round trips, h5py reading our files, refused corrupt inputs.
#include <gtest/gtest.h>
#include <sys/stat.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <fstream>
#include <iterator>
#include <opencv2/imgcodecs.hpp>
#include <sstream>

#include "core/base/errors.hpp"
#include "core/io/atomic_file.hpp"
#include "core/io/checksum.hpp"
#include "core/io/direct_writer.hpp"
#include "core/io/hdf5_files.hpp"
#include "core/io/raw_frame.hpp"
#include "core/io/tiff.hpp"
#include "core/io/vtk_files.hpp"
#include "tests/support/child_process.hpp"
#include "tests/support/input_error.hpp"
#include "tests/support/temp_dir.hpp"
#include "tests/support/tmpfs.hpp"

namespace plenopiv::io {
namespace {

std::filesystem::path temp_dir() { return testing_support::temp_dir("io-test"); }

using testing_support::error_of;

Volume ramp_volume() {
  Grid3 g;
  g.shape = {5, 4, 3};
  g.origin_mm = {-1.0, -0.5, -0.25};
  g.spacing_mm = {0.125, 0.25, 0.5};
  Volume v(g);
  for (std::size_t i = 0; i < v.data.size(); ++i) v.data[i] = float(i) * 0.5f;
  return v;
}

VectorField some_field() {
  Grid3 g;
  g.shape = {3, 2, 2};
  g.origin_mm = {1, 2, 3};
  g.spacing_mm = {0.5, 0.5, 1.0};
  VectorField f(g);
  for (std::size_t i = 0; i < g.count(); ++i) {
    f.dx_mm[i] = 0.01f * float(i);
    f.dy_mm[i] = -0.02f * float(i);
    f.dz_mm[i] = 0.03f;
    f.valid[i] = i % 2;
    f.peak_ratio[i] = 1.5f;
  }
  f.dt_s = 1e-3;
  return f;
}

TEST(Tiff, SixteenBitRoundTrip) {
  ImageU16 img(7, 5);
  for (std::size_t i = 0; i < img.size(); ++i) img.pixels[i] = std::uint16_t(i * 1000);
  const auto path = temp_dir() / "img.tif";
  write_tiff(path, img);
  const ImageU16 back = read_tiff_u16(path);
  EXPECT_EQ(back.width, 7);
  EXPECT_EQ(back.height, 5);
  EXPECT_EQ(back.pixels, img.pixels);
}

// Our reader and another (OpenCV's) read `path` back as `img`, pixel for pixel.
void expect_read_back_by_both_readers(const std::filesystem::path& path, const ImageU16& img) {
  EXPECT_EQ(read_tiff_u16(path).pixels, img.pixels);
  const cv::Mat other = cv::imread(path.string(), cv::IMREAD_UNCHANGED);
  ASSERT_EQ(other.type(), CV_16U);
  ASSERT_EQ(other.cols, img.width);
  ASSERT_EQ(other.rows, img.height);
  for (int y = 0; y < img.height; ++y)
    for (int x = 0; x < img.width; ++x) ASSERT_EQ(other.at<std::uint16_t>(y, x), img.at(x, y)) << x << ", " << y;
}

// A camera frame is written strip by strip straight from its pixels (the last strip shorter):
// another reader (OpenCV's) sees the same counts.
TEST(Tiff, AFrameOfManyStripsReadsBackBitForBitInAnotherReader) {
  ImageU16 img(1000, 301);  // 2000-byte rows: 32 rows a strip, 10 strips, the last of 13 rows
  for (std::size_t i = 0; i < img.size(); ++i) img.pixels[i] = std::uint16_t(i * 2654435761u >> 11);
  const auto path = temp_dir() / "strips.tif";
  write_tiff(path, img);
  expect_read_back_by_both_readers(path, img);
}

// A frame larger than the direct writer's staging buffer (several of them, the last part short)
// reads back bit for bit in both readers.
TEST(Tiff, AFrameLargerThanTheStagingBufferReadsBackBitForBit) {
  ImageU16 img(3001, 1601);  // 9.6 MB
  for (std::size_t i = 0; i < img.size(); ++i) img.pixels[i] = std::uint16_t(i * 40503u >> 3);
  const auto path = temp_dir() / "large.tif";
  write_tiff(path, img);
  expect_read_back_by_both_readers(path, img);
}

// A file system's direct-I/O alignments (statx) that 4 KiB blocks meet, and those they do not: then
// the writer writes through the page cache instead of failing its first write.
TEST(DirectWriter, TakesO_DIRECTOnlyWhereFourKiBBlocksMeetTheReportedAlignment) {
  EXPECT_TRUE(DirectWriter::alignment_fits(512, 512));    // ext4 on this machine's disk
  EXPECT_TRUE(DirectWriter::alignment_fits(4, 512));      // memory aligned more loosely than offsets
  EXPECT_TRUE(DirectWriter::alignment_fits(4096, 4096));  // a 4K-sector device
  EXPECT_FALSE(DirectWriter::alignment_fits(8192, 8192)) << "a device with 8 KiB logical blocks";
  EXPECT_FALSE(DirectWriter::alignment_fits(512, 16384));
  EXPECT_FALSE(DirectWriter::alignment_fits(0, 0)) << "no direct I/O for this file";
}

// The direct writer behaves as a file handle: sequential writes across staging buffers, a seek back
// into the first block and into blocks already written, a gap past the end (zeros); the file holds
// exactly what a buffered file would. Tried where /tmp is (O_DIRECT on most file systems).
TEST(DirectWriter, AnyPatternOfWritesLeavesWhatAFileHandleWould) {
  const auto path = temp_dir() / "direct.bin";
  std::vector<unsigned char> expected;
  const auto put = [&](std::size_t at, std::size_t n, unsigned seed) {
    if (expected.size() < at + n) expected.resize(at + n, 0);
    for (std::size_t i = 0; i < n; ++i) expected[at + i] = static_cast<unsigned char>((seed + i) * 2654435761u >> 24);
  };
  {
    DirectWriter w(path);
    EXPECT_EQ(w.mode(), direct_write_mode(path.parent_path()));
    std::vector<unsigned char> chunk;
    const auto write_at = [&](std::size_t at, std::size_t n, unsigned seed) {
      put(at, n, seed);
      chunk.assign(expected.begin() + std::ptrdiff_t(at), expected.begin() + std::ptrdiff_t(at + n));
      EXPECT_EQ(w.seek(std::int64_t(at), SEEK_SET), at);
      w.write(chunk.data(), n);
    };
    write_at(0, 8, 1);  // a header
    std::size_t at = 8;
    for (unsigned k = 0; at < 9'500'000; ++k) {  // strips of odd sizes, across 4 MiB buffers
      const std::size_t n = 1 + (k * 7919u) % 70'000;
      write_at(at, n, k + 2);
      at += n;
    }
    write_at(4, 4, 99);              // the header again
    write_at(5000, 3000, 100);       // inside a block already on the disk
    write_at(4'194'000, 9000, 101);  // across the first buffer's end, on the disk
    EXPECT_EQ(w.seek(0, SEEK_END), at);
    write_at(at + 12'345, 10, 102);  // past the end: a gap of zeros
    EXPECT_EQ(w.size(), expected.size());
    w.finish();
  }
  std::ifstream in(path, std::ios::binary);
  const std::vector<unsigned char> back((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  ASSERT_EQ(back.size(), expected.size());
  EXPECT_TRUE(back == expected);
}

// A full disk surfaces from the write that meets it or from finish(), naming the file and the
// reason; write_tiff then leaves nothing under the name.
TEST(DirectWriter, AFullDiskIsNamedAndLeavesNoFile) {
  testing_support::SmallTmpfs disk(temp_dir() / "full-direct", 2);
  if (!disk.mounted()) GTEST_SKIP() << disk.why_not();
  ImageU16 img(1500, 1000);  // 3 MB on a 2 MB disk
  const auto path = disk.dir() / "frame.tif";
  try {
    write_tiff(path, img);
    ADD_FAILURE() << "wrote 3 MB on a 2 MB disk";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("no space left on device"), std::string::npos) << e.what();
  }
  EXPECT_TRUE(std::filesystem::is_empty(disk.dir()));
}

// The write-rate probe: a rate, its file kept and overwritten in place (never truncated, which
// would trim its blocks on a `discard` mount), chunks that differ, and a full disk or a missing
// folder named.
TEST(WriteRate, TheProbeIsMeasuredKeptAndOverwrittenInPlace) {
  const auto dir = temp_dir() / "write-rate";
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  const auto probe = dir / kWriteProbeName;
  const double first = measure_write_rate(dir, 20u << 20);  // three 8 MiB chunks
  EXPECT_GT(first, 1e6) << "bytes per second";
  ASSERT_EQ(std::filesystem::file_size(probe), std::uintmax_t(24) << 20);
  struct stat before {};
  ASSERT_EQ(::stat(probe.c_str(), &before), 0);
  std::ifstream in(probe, std::ios::binary);
  std::vector<char> start(64), next(64);
  in.read(start.data(), 64);
  in.seekg(8 << 20);
  in.read(next.data(), 64);
  EXPECT_NE(start, next) << "every chunk's bytes differ";
  in.close();
  const double second = measure_write_rate(dir, 1);  // one chunk, over the first
  EXPECT_GT(second, 1e6);
  struct stat after {};
  ASSERT_EQ(::stat(probe.c_str(), &after), 0);
  EXPECT_EQ(after.st_ino, before.st_ino) << "the same file, not a new one";
  EXPECT_EQ(std::filesystem::file_size(probe), std::uintmax_t(24) << 20) << "not truncated";
  try {
    measure_write_rate(dir / "missing", 1);
    ADD_FAILURE() << "a missing folder";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find((dir / "missing" / kWriteProbeName).string()), std::string::npos) << e.what();
  }
  testing_support::SmallTmpfs disk(temp_dir() / "full-rate", 4);
  if (!disk.mounted()) GTEST_SKIP() << disk.why_not();
  try {
    measure_write_rate(disk.dir(), 16u << 20);
    ADD_FAILURE() << "wrote 16 MiB on a 4 MB disk";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("space left on device"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find(kWriteProbeName), std::string::npos) << e.what();
  }
  EXPECT_TRUE(std::filesystem::is_empty(disk.dir())) << "a probe not written whole does not fill the disk";
}

// Read into a frame buffer: reused when it has the file's size, replaced when not.
TEST(Tiff, AFrameIsReadIntoABufferOfItsSize) {
  ImageU16 img(9, 4);
  for (std::size_t i = 0; i < img.size(); ++i) img.pixels[i] = std::uint16_t(3 * i + 1);
  const auto path = temp_dir() / "into.tif";
  write_tiff(path, img);
  ImageU16 buffer(9, 4, 7);
  const std::uint16_t* kept = buffer.pixels.data();
  read_tiff_u16(path, buffer);
  EXPECT_EQ(buffer.pixels, img.pixels);
  EXPECT_EQ(buffer.pixels.data(), kept);
  ImageU16 other(4, 9);
  read_tiff_u16(path, other);
  EXPECT_EQ(other.width, 9);
  EXPECT_EQ(other.height, 4);
  EXPECT_EQ(other.pixels, img.pixels);
}

TEST(Tiff, FloatStackRoundTrip) {
  std::vector<ImageF> pages;
  for (int p = 0; p < 3; ++p) {
    ImageF page(4, 3);
    for (std::size_t i = 0; i < page.size(); ++i) page.pixels[i] = float(p) + 0.25f * float(i);
    pages.push_back(page);
  }
  const auto path = temp_dir() / "stack.tif";
  write_tiff_stack(path, pages);
  const auto back = read_tiff_stack(path);
  ASSERT_EQ(back.size(), 3u);
  for (int p = 0; p < 3; ++p) EXPECT_EQ(back[p].pixels, pages[p].pixels);
}

TEST(Tiff, CorruptAndMissingFilesAreNamed) {
  const auto path = temp_dir() / "corrupt.tif";
  std::ofstream(path) << "II*\0 this is not a tiff";
  const std::string corrupt = error_of([&] { read_tiff_u16(path); });
  EXPECT_NE(corrupt.find(path.string()), std::string::npos) << corrupt;
  const std::string missing = error_of([&] { read_tiff_u16(temp_dir() / "nope.tif"); });
  EXPECT_NE(missing.find("nope.tif: cannot open as TIFF"), std::string::npos) << missing;
}

TEST(Tiff, FloatImageIsNotARawFrame) {
  const auto path = temp_dir() / "float.tif";
  write_tiff_stack(path, {ImageF(3, 3, 1.f)});
  const std::string err = error_of([&] { read_tiff_u16(path); });
  EXPECT_NE(err.find("expected a single-channel 8- or 16-bit unsigned TIFF"), std::string::npos) << err;
}

// One reader for raw frames, whatever a camera's software saved: PNG (8/16-bit), TIFF (8/16-bit or
// float), told apart by their signature; everything else refused by name.
TEST(RawFrame, PngAndTiffOfEveryDepthReadAsCounts) {
  const auto dir = temp_dir() / "frames";
  std::filesystem::create_directories(dir);
  cv::Mat grey8(3, 4, CV_8U), grey16(3, 4, CV_16U);
  for (int y = 0; y < 3; ++y)
    for (int x = 0; x < 4; ++x) {
      grey8.at<std::uint8_t>(y, x) = std::uint8_t(10 * y + x);
      grey16.at<std::uint16_t>(y, x) = std::uint16_t(1000 * y + x);
    }
  ASSERT_TRUE(cv::imwrite((dir / "a.png").string(), grey8));
  ASSERT_TRUE(cv::imwrite((dir / "b.png").string(), grey16));
  ASSERT_TRUE(cv::imwrite((dir / "c.tif").string(), grey8));
  ImageU16 u16(4, 3);
  for (std::size_t k = 0; k < u16.size(); ++k) u16.pixels[k] = std::uint16_t(60000 + k);
  write_tiff(dir / "d.tif", u16);
  ImageF f32(4, 3);
  for (std::size_t k = 0; k < f32.size(); ++k) f32.pixels[k] = 0.25f * float(k) - 1.0f;
  write_tiff_stack(dir / "e.tif", {f32});
  // A name says nothing: a PNG saved as .tif is read as the PNG it is.
  std::filesystem::copy_file(dir / "a.png", dir / "a_really_png.tif",
                             std::filesystem::copy_options::overwrite_existing);

  const ImageF a = read_raw_frame(dir / "a.png"), b = read_raw_frame(dir / "b.png"), c = read_raw_frame(dir / "c.tif");
  const ImageF d = read_raw_frame(dir / "d.tif"), e = read_raw_frame(dir / "e.tif");
  const ImageF renamed = read_raw_frame(dir / "a_really_png.tif");
  ASSERT_EQ(a.width, 4);
  ASSERT_EQ(a.height, 3);
  for (int y = 0; y < 3; ++y)
    for (int x = 0; x < 4; ++x) {
      EXPECT_EQ(a.at(x, y), float(10 * y + x));
      EXPECT_EQ(b.at(x, y), float(1000 * y + x));
      EXPECT_EQ(c.at(x, y), float(10 * y + x));
      EXPECT_EQ(renamed.at(x, y), float(10 * y + x));
    }
  EXPECT_EQ(d.pixels[11], 60011.0f);
  EXPECT_EQ(e.pixels, f32.pixels);  // float frames keep their values, negative ones too

  // A series: averaged; a frame of another size named.
  const ImageF mean =
      read_mean_frame({(dir / "a.png").string(), (dir / "c.tif").string(), (dir / "b.png").string()}, "white");
  EXPECT_FLOAT_EQ(mean.at(3, 2), (23.0f + 23.0f + 2003.0f) / 3);
  ASSERT_TRUE(cv::imwrite((dir / "small.png").string(), cv::Mat(2, 2, CV_8U, cv::Scalar(1))));
  const std::string err = error_of([&] {
    read_mean_frame({(dir / "a.png").string(), (dir / "small.png").string()}, "dark");
  });
  EXPECT_NE(err.find("small.png: dark frame is 2 x 2 pixels, "), std::string::npos) << err;
  EXPECT_NE(err.find("a.png is 4 x 3"), std::string::npos) << err;
}

TEST(RawFrame, ColourNonFiniteCorruptAndForeignFilesAreRefusedByName) {
  const auto dir = temp_dir() / "bad-frames";
  std::filesystem::create_directories(dir);
  // Grey stored as colour (equal channels) is grey; real colour is not a raw frame.
  ASSERT_TRUE(cv::imwrite((dir / "grey_rgb.png").string(), cv::Mat(2, 3, CV_8UC3, cv::Scalar(7, 7, 7))));
  EXPECT_EQ(read_raw_frame(dir / "grey_rgb.png").pixels, HugePageVector<float>(6, 7.0f));
  ASSERT_TRUE(cv::imwrite((dir / "colour.png").string(), cv::Mat(2, 3, CV_8UC3, cv::Scalar(7, 8, 9))));
  std::string err = error_of([&] { read_raw_frame(dir / "colour.png"); });
  EXPECT_NE(err.find("colour.png: a colour PNG"), std::string::npos) << err;

  ImageF nan(3, 2, 1.0f);
  nan.at(2, 1) = std::nanf("");
  write_tiff_stack(dir / "nan.tif", {nan});
  err = error_of([&] { read_raw_frame(dir / "nan.tif"); });
  EXPECT_NE(err.find("nan.tif: pixel (2, 1) is nan; a raw frame's values must be finite"), std::string::npos) << err;

  std::ofstream(dir / "text.png") << "just some text, not an image";
  err = error_of([&] { read_raw_frame(dir / "text.png"); });
  EXPECT_NE(err.find("text.png: not a PNG or TIFF file"), std::string::npos) << err;
  {
    std::ofstream bad(dir / "cut.png", std::ios::binary);
    bad << "\x89PNG\r\n\x1a\n" << std::string(40, 'x');
  }
  err = error_of([&] { read_raw_frame(dir / "cut.png"); });
  EXPECT_NE(err.find("cut.png: corrupt or unreadable PNG"), std::string::npos) << err;
  err = error_of([&] { read_raw_frame(dir / "missing.png"); });
  EXPECT_NE(err.find("missing.png: no such file"), std::string::npos) << err;
  err = error_of([&] { read_raw_frame(dir / "cut.tif"); });
  EXPECT_NE(err.find("cut.tif: no such file"), std::string::npos) << err;
  {
    const std::string head("II*\0 and then nothing useful", 29);
    std::ofstream(dir / "cut.tif", std::ios::binary).write(head.data(), std::streamsize(head.size()));
  }
  err = error_of([&] { read_raw_frame(dir / "cut.tif"); });
  EXPECT_NE(err.find("cut.tif: cannot open as TIFF"), std::string::npos) << err;
}

TEST(AtomicFile, AFailedWriteLeavesNothingBehind) {
  const auto dir = temp_dir() / "atomic";
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  EXPECT_THROW(write_atomically(dir / "out.h5",
                                [](const std::filesystem::path& tmp) {
                                  std::ofstream(tmp) << "half";
                                  throw std::runtime_error("disk full");
                                }),
               std::runtime_error);
  EXPECT_TRUE(std::filesystem::is_empty(dir));
  const std::string err = error_of([&] { write_volume_h5(dir / "missing/v.h5", ramp_volume()); });
  EXPECT_NE(err.find("does not exist"), std::string::npos) << err;
}

TEST(FileBytes, EveryByteOfEmptySmallAndLargeFilesReadMappedAndTheirCrcWholeOrInPieces) {
  const auto dir = temp_dir() / "file_bytes";
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  std::string large((3u << 20) + 12345, '\0');  // pieces of 1 MiB and a rest
  for (std::size_t i = 0; i < large.size(); ++i) large[i] = char((i * 2654435761u) >> 24);
  for (const std::string& bytes : {std::string(), std::string("a\0b\n", 4), large}) {
    const auto file = dir / ("f" + std::to_string(bytes.size()));
    std::ofstream(file, std::ios::binary).write(bytes.data(), std::streamsize(bytes.size()));
    EXPECT_EQ(read_file_bytes(file), bytes) << bytes.size() << " bytes";
    EXPECT_EQ(MappedFile(file).bytes(), bytes) << bytes.size() << " bytes";
    const FileChecksum sum = checksum_of_file(file);
    EXPECT_EQ(sum.crc32, crc32_of(bytes)) << bytes.size() << " bytes";
    EXPECT_EQ(sum.bytes, bytes.size());
  }
  // zlib's CRC-32 of "123456789", the check value of the CRC-32/ISO-HDLC catalogue entry.
  EXPECT_EQ(crc32_hex(crc32_of("123456789")), "cbf43926");
  for (const auto& bad : {dir / "missing", dir}) {
    for (const std::string& err : {error_of([&] { read_file_bytes(bad); }), error_of([&] { checksum_of_file(bad); }),
                                   error_of([&] { MappedFile m(bad); })})
      EXPECT_NE(err.find(bad.string()), std::string::npos) << err;
  }
  // A mapped file replaced by a rename (as io::write_atomically replaces one) or removed keeps the
  // bytes it had when mapped.
  const auto file = dir / "replaced";
  std::ofstream(file, std::ios::binary) << "old bytes";
  const MappedFile mapped(file);
  std::ofstream(dir / "new", std::ios::binary) << "new and longer bytes";
  std::filesystem::rename(dir / "new", file);
  EXPECT_EQ(mapped.bytes(), "old bytes");
  std::filesystem::remove(file);
  EXPECT_EQ(mapped.bytes(), "old bytes");
}

// Frames and volumes of 2 MB or more start on a 2 MB boundary (where a huge page can back them)
// and are zeroed as a std::vector is; smaller ones are plain allocations, zeroed too.
TEST(HugePages, LargeImagesAndVolumesStartOnA2MbBoundaryAndAreZeroed) {
  const auto on_boundary = [](const void* p) {
    return reinterpret_cast<std::uintptr_t>(p) % (std::size_t(2) << 20) == 0;
  };
  const ImageF frame(2048, 1025);  // just over 8 MB
  EXPECT_TRUE(on_boundary(frame.pixels.data()));
  EXPECT_EQ(std::count(frame.pixels.begin(), frame.pixels.end(), 0.f), std::ptrdiff_t(frame.size()));
  Grid3 g;
  g.shape = {128, 128, 40};  // 2.5 MB
  const Volume volume(g);
  EXPECT_TRUE(on_boundary(volume.data.data()));
  EXPECT_EQ(std::count(volume.data.begin(), volume.data.end(), 0.f), std::ptrdiff_t(volume.data.size()));
  const ImageU16 small(16, 16, 7);
  EXPECT_EQ(std::count(small.pixels.begin(), small.pixels.end(), std::uint16_t(7)), 256);
  ImageF copy = frame;  // a copy takes its own block
  EXPECT_TRUE(on_boundary(copy.pixels.data()));
  EXPECT_NE(copy.pixels.data(), frame.pixels.data());
}

TEST(Hdf5, VolumeRoundTrip) {
  const Volume v = ramp_volume();
  const auto path = temp_dir() / "volume.h5";
  write_volume_h5(path, v);
  const Volume back = read_volume_h5(path);
  EXPECT_EQ(back.grid, v.grid);
  EXPECT_EQ(back.data, v.data);
}

TEST(Hdf5, VectorFieldRoundTrip) {
  const VectorField f = some_field();
  const auto path = temp_dir() / "field.h5";
  write_vector_field_h5(path, f, {{"vorticity_z", std::vector<float>(f.grid.count(), 2.f), "1/s"}});
  const VectorField back = read_vector_field_h5(path);
  EXPECT_EQ(back.grid, f.grid);
  EXPECT_EQ(back.dx_mm, f.dx_mm);
  EXPECT_EQ(back.dy_mm, f.dy_mm);
  EXPECT_EQ(back.dz_mm, f.dz_mm);
  EXPECT_EQ(back.valid, f.valid);
  EXPECT_EQ(back.peak_ratio, f.peak_ratio);
  EXPECT_DOUBLE_EQ(back.dt_s, f.dt_s);
  EXPECT_EQ(read_provenance(path, "software").value_or("").rfind("plenopiv ", 0), 0u);
  EXPECT_FALSE(read_provenance(path, "no_such_entry").has_value());
  EXPECT_FALSE(read_provenance(temp_dir() / "no_such_file.h5", "software").has_value());
  // A settings text too long for an HDF5 attribute is kept whole.
  std::string long_settings;
  for (int i = 0; i < 20000; ++i) long_settings += "k" + std::to_string(i) + ": 1\n";
  ASSERT_GT(long_settings.size(), 65536u);
  write_vector_field_h5(path, f, {}, {{"settings", long_settings}});
  EXPECT_EQ(read_provenance(path, "settings"), long_settings);
  EXPECT_TRUE(back.sigma_dx_mm.empty());  // a field without an uncertainty has none in its file
}

// The per-vector uncertainty is written as sigma_u, sigma_v, sigma_w (m/s, with units and axes
// like u, v, w), NaN where a vector has none, and read back in mm; the .vti carries it as one
// 3-component array.
TEST(Hdf5, VectorFieldUncertaintyRoundTrip) {
  VectorField f = some_field();
  for (auto* s : {&f.sigma_dx_mm, &f.sigma_dy_mm, &f.sigma_dz_mm}) s->assign(f.grid.count(), 0.002f);
  f.sigma_dz_mm[3] = NAN;
  f.sigma_method = "correlation statistics of the final pass (Wieneke 2015): a test's";
  const auto path = temp_dir() / "field_sigma.h5";
  write_vector_field_h5(path, f);
  const VectorField back = read_vector_field_h5(path);
  EXPECT_EQ(back.sigma_method, f.sigma_method);
  ASSERT_EQ(back.sigma_dz_mm.size(), f.grid.count());
  EXPECT_NEAR(back.sigma_dx_mm[0], 0.002, 1e-9);
  EXPECT_TRUE(std::isnan(back.sigma_dz_mm[3]));
  std::string out;
  ASSERT_EQ(testing_support::run_command({"/usr/bin/python3", "-c",
                                          "import h5py, sys; g = h5py.File(sys.argv[1])['vectors']; s = g['sigma_w']; "
                                          "u = s.attrs['units']; print(u.decode() if isinstance(u, bytes) else u, "
                                          "[d[0].name for d in s.dims], round(float(g['sigma_u'][0, 0, 0]), 6)); "
                                          "t = lambda a: a.decode() if isinstance(a, bytes) else a; "
                                          "print(t(s.attrs['long_name'])); print(t(g.attrs['sigma_method']))",
                                          path.string()},
                                         out),
            0)
      << out;
  EXPECT_NE(out.find("m/s ['/vectors/z', '/vectors/y', '/vectors/x'] 0.002"), std::string::npos) << out;
  // What sigma holds, beside it: in each array's long_name and as the group's attribute.
  EXPECT_NE(out.find("\nstandard uncertainty of w (" + f.sigma_method + "); NaN: no estimate"), std::string::npos)
      << out;
  EXPECT_NE(out.find("\n" + f.sigma_method + "\n"), std::string::npos) << out;
  const auto vti = temp_dir() / "field_sigma.vti";
  write_vector_field_vti(vti, f);
  std::ifstream in(vti);
  const std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  EXPECT_NE(text.find("Name=\"sigma_velocity_m_s\" NumberOfComponents=\"3\""), std::string::npos);
  f.sigma_dy_mm.pop_back();
  EXPECT_THROW(write_vector_field_h5(path, f), InputError);
}

TEST(Hdf5, PythonH5pyReadsTheLayoutOfTheDesign) {
  const auto vpath = temp_dir() / "py_volume.h5";
  const auto fpath = temp_dir() / "py_field.h5";
  write_volume_h5(vpath, ramp_volume());
  const VectorField field = some_field();
  std::vector<std::uint8_t> bits(field.grid.count(), 0);
  bits[1] = 5;
  write_vector_field_h5(fpath, field, {{"vorticity_z", std::vector<float>(field.grid.count(), 2.f), "1/s"}},
                        {{"settings", "mart:\n  iterations: 8\n"}}, FlagField{"flags", bits, "1: one; 4: four"});
  const std::string script =
      "import h5py, numpy as np, sys\n"
      "v = h5py.File(sys.argv[1], 'r')['volume']\n"
      "assert v.shape == (3, 4, 5) and v.dtype == np.float32, v.shape\n"
      "assert np.allclose(v.attrs['origin_mm'], [-1.0, -0.5, -0.25])\n"
      "assert np.allclose(v.attrs['spacing_mm'], [0.125, 0.25, 0.5])\n"
      "assert v[2, 3, 4] == 0.5 * 59\n"
      "g = h5py.File(sys.argv[2], 'r')['vectors']\n"
      "assert np.allclose(g['x'][:], [1, 1.5, 2]) and np.allclose(g['z'][:], [3, 4])\n"
      "assert g['u'].shape == (2, 2, 3) and g['valid'].dtype == np.uint8\n"
      "assert np.allclose(g['u'][:], g['dx'][:] * 1e-3 / 1e-3)\n"
      "assert np.allclose(g['w'][:], 0.03)\n"
      "assert abs(g.attrs['dt_s'] - 1e-3) < 1e-15\n"
      "f = h5py.File(sys.argv[2], 'r')\n"
      "units = {n: g[n].attrs['units'] for n in g}\n"
      "units = {n: u.decode() if isinstance(u, bytes) else u for n, u in units.items()}\n"
      "assert units['u'] == 'm/s' and units['dx'] == 'mm' and units['x'] == 'mm', units\n"
      "assert units['vorticity_z'] == '1/s' and units['flags'] == '1', units\n"
      "for name in ('u', 'dx', 'valid', 'vorticity_z', 'flags'):\n"
      "    ds = g[name]\n"
      "    assert [d[0].name for d in ds.dims] == ['/vectors/z', '/vectors/y', '/vectors/x'], name\n"
      "assert g['flags'].dtype == np.uint8 and g['flags'][0, 0, 1] == 5\n"
      "legend = g['flags'].attrs['legend']\n"
      "assert (legend.decode() if isinstance(legend, bytes) else legend) == '1: one; 4: four'\n"
      "vf = h5py.File(sys.argv[1], 'r')\n"
      "assert [d[0].name for d in vf['volume'].dims] == ['/z', '/y', '/x']\n"
      "assert np.allclose(vf['x'][:], -1.0 + 0.125 * np.arange(5))\n"
      "def text(a): return a.decode() if isinstance(a, bytes) else a\n"
      "p = f['provenance'].attrs\n"
      "assert text(p['software']).startswith('plenopiv '), p['software']\n"
      "assert text(p['commit']) and text(p['host']) and text(p['written_utc']).endswith('Z')\n"
      "assert text(p['settings']) == 'mart:\\n  iterations: 8\\n', p['settings']\n"
      "assert text(vf['provenance'].attrs['software']).startswith('plenopiv ')\n"
      "print('h5py ok')\n";
  const auto script_path = temp_dir() / "check.py";
  std::ofstream(script_path) << script;
  if (!std::filesystem::exists("/usr/bin/python3")) GTEST_SKIP() << "/usr/bin/python3 missing";
  std::string out;
  const int rc =
      testing_support::run_command({"/usr/bin/python3", script_path.string(), vpath.string(), fpath.string()}, out);
  EXPECT_EQ(rc, 0) << out;
  EXPECT_NE(out.find("h5py ok"), std::string::npos) << out;
}

TEST(Hdf5, WrongFilesAreNamed) {
  const auto text = temp_dir() / "text.h5";
  std::ofstream(text) << "not hdf5";
  EXPECT_NE(error_of([&] { read_volume_h5(text); }).find("not an HDF5 file"), std::string::npos);
  const auto field = temp_dir() / "field_only.h5";
  write_vector_field_h5(field, some_field());
  EXPECT_NE(error_of([&] { read_volume_h5(field); }).find("no dataset volume"), std::string::npos);
  const auto vol = temp_dir() / "volume_only.h5";
  write_volume_h5(vol, ramp_volume());
  EXPECT_NE(error_of([&] { read_vector_field_h5(vol); }).find("no group /vectors"), std::string::npos);
  VectorField no_dt = some_field();
  no_dt.dt_s = 0;
  EXPECT_NE(error_of([&] { write_vector_field_h5(temp_dir() / "nodt.h5", no_dt); }).find("dt_s"), std::string::npos);
  // A file of a few KB that declares a 4 PB volume (chunks never written read as the fill value):
  // refused with what it would need, before anything is allocated.
  const auto huge = temp_dir() / "huge.h5";
  std::string out;
  ASSERT_EQ(testing_support::run_command({"/usr/bin/python3", "-c",
                                          "import h5py, sys\n"
                                          "with h5py.File(sys.argv[1], 'w') as f:\n"
                                          "    v = f.create_dataset('volume', shape=(100000,) * 3, dtype='f4', "
                                          "chunks=(1, 64, 64))\n"
                                          "    v.attrs['origin_mm'] = [0.0, 0.0, 0.0]\n"
                                          "    v.attrs['spacing_mm'] = [1.0, 1.0, 1.0]\n",
                                          huge.string()},
                                         out),
            0)
      << out;
  const std::string refused = error_of([&] { read_volume_h5(huge); });
  EXPECT_NE(refused.find("dataset volume needs"), std::string::npos) << refused;
  EXPECT_NE(refused.find("more than this machine's"), std::string::npos) << refused;
}

TEST(Vti, HeaderAndAppendedSizesDescribeTheArrays) {
  const auto path = temp_dir() / "volume.vti";
  const Volume v = ramp_volume();
  write_volume_vti(path, v);
  std::ifstream in(path, std::ios::binary);
  std::stringstream s;
  s << in.rdbuf();
  const std::string text = s.str();
  EXPECT_NE(text.find("WholeExtent=\"0 4 0 3 0 2\""), std::string::npos);
  EXPECT_NE(text.find("Spacing=\"0.125 0.25 0.5\""), std::string::npos);
  EXPECT_NE(text.find("Name=\"intensity\""), std::string::npos);
  const auto start = text.find("_", text.find("<AppendedData")) + 1;
  std::uint64_t n = 0;
  std::memcpy(&n, text.data() + start, sizeof n);
  EXPECT_EQ(n, v.data.size() * sizeof(float));
  float last = 0;
  std::memcpy(&last, text.data() + start + sizeof n + n - sizeof(float), sizeof last);
  EXPECT_EQ(last, v.data.back());

  const auto fpath = temp_dir() / "field.vti";
  write_vector_field_vti(fpath, some_field());
  std::ifstream fin(fpath);
  std::stringstream fs;
  fs << fin.rdbuf();
  EXPECT_NE(fs.str().find("Name=\"velocity_m_s\" NumberOfComponents=\"3\""), std::string::npos);
}

// A full disk is named as such with the path and the space left, and leaves neither a temporary
// file nor a damaged target behind.
TEST(AtomicFile, AFullDiskIsNamedAndLeavesTheOldFileWhole) {
  testing_support::SmallTmpfs disk(temp_dir() / "full-disk", 1);
  if (!disk.mounted()) GTEST_SKIP() << disk.why_not();
  const std::filesystem::path target = disk.dir() / "frame.tif";
  write_tiff(target, ImageU16(100, 100, 7));  // an old version that fits
  try {
    write_tiff(target, ImageU16(1024, 1024, 9));  // 2 MiB: does not fit in 1 MiB
    FAIL() << "a 2 MiB frame was written to a 1 MiB disk";
  } catch (const std::runtime_error& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find(target.string() + ": no space left on device"), std::string::npos) << what;
    EXPECT_NE(what.find("free in " + disk.dir().string()), std::string::npos) << what;
    EXPECT_EQ(what.find("Success"), std::string::npos) << what;
  }
  EXPECT_EQ(read_tiff_u16(target).pixels, ImageU16(100, 100, 7).pixels);
  for (const auto& entry : std::filesystem::directory_iterator(disk.dir())) {
    EXPECT_EQ(entry.path().filename().string().find(".tmp"), std::string::npos) << entry.path();
  }
  // HDF5 the same way.
  Grid3 g;
  g.shape = {128, 128, 32};
  try {
    write_volume_h5(disk.dir() / "volume.h5", Volume(g, 1.f));
    FAIL() << "a 2 MiB volume was written to a 1 MiB disk";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("no space left on device"), std::string::npos) << e.what();
  }
  EXPECT_FALSE(std::filesystem::exists(disk.dir() / "volume.h5"));
}

}  // namespace
}  // namespace plenopiv::io
