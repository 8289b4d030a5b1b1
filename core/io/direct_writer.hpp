// A new file written past the page cache (O_DIRECT) through aligned staging buffers.
#pragma once

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <memory>

namespace plenopiv::io {

// How a DirectWriter reaches the disk.
enum class WriteMode {
  direct,    // O_DIRECT: from the staging buffer to the device, no page cache
  buffered,  // the file system refuses O_DIRECT (EINVAL), or asks for an alignment that kBlock is
             // not a multiple of: ordinary writes of the same blocks
};

// Written this way, a recorder's raw frames at hundreds of MB/s cost a copy, not page-cache churn.
// Writes one new file (created or truncated, mode 0644) at any offsets, as a file handle does:
// libtiff's client I/O (header, strips, directory, then the header again) fits it. Bytes go into a
// staging buffer aligned to kBlock and reach the file in whole blocks; the file's first block stays
// in memory until finish(), so rewriting the header costs no read. A write into an earlier block
// reads, patches and writes that block again. Gaps read as zeros. finish() writes the rest and cuts
// the file to its size; without it (an error) the file holds an unspecified prefix and the caller
// removes it. Errors are std::runtime_error naming the file and the system's reason (errno kept).
class DirectWriter {
 public:
  // O_DIRECT alignment of offsets, lengths and memory: a 4 KiB logical block covers 512-byte
  // and 4K-sector devices alike.
  static constexpr std::size_t kBlock = 4096;
  // Whether kBlock-aligned memory, offsets and lengths meet the direct-I/O alignments a file system
  // reports for a file (statx STATX_DIOALIGN: memory and offset, bytes; 0: no direct I/O there).
  static bool alignment_fits(std::uint32_t memory_align, std::uint32_t offset_align);

  explicit DirectWriter(const std::filesystem::path& path);
  ~DirectWriter();
  DirectWriter(const DirectWriter&) = delete;
  DirectWriter& operator=(const DirectWriter&) = delete;

  WriteMode mode() const { return mode_; }
  // Copies `n` bytes to the current position and moves past them.
  void write(const void* data, std::size_t n);
  // Sets the current position (SEEK_SET, SEEK_CUR or SEEK_END semantics); returns it.
  std::uint64_t seek(std::int64_t offset, int whence);
  std::uint64_t size() const { return size_; }
  // Writes what is staged and the first block, and cuts the file to size(). Once only.
  void finish();

 private:
  void write_blocks(const unsigned char* data, std::size_t bytes, std::uint64_t offset);
  void zero_staged_to(std::size_t end);
  void flush_staged();
  void patch_flushed(const unsigned char* data, std::size_t n, std::uint64_t offset);
  [[noreturn]] void fail(const char* what) const;

  std::filesystem::path path_;
  int fd_ = -1;
  WriteMode mode_ = WriteMode::direct;
  struct Buffer;
  std::unique_ptr<Buffer> head_;    // the file's first block
  std::unique_ptr<Buffer> staged_;  // file bytes [base_, base_ + capacity)
  std::size_t staged_filled_ = 0;   // staged_'s first bytes that hold the file's (written or zeros)
  std::uint64_t base_ = kBlock;     // blocks before base_ (but the first) are on the disk
  std::uint64_t position_ = 0;
  std::uint64_t size_ = 0;
  bool finished_ = false;
};

// Whether files in `folder` can be written with O_DIRECT (a probe file is made and removed).
WriteMode direct_write_mode(const std::filesystem::path& folder);

// The file measure_write_rate writes in its folder, kept between calls.
inline constexpr const char* kWriteProbeName = ".plenopiv-write-probe";
// The rate at which `folder` takes a recorder's writes, bytes per second: `bytes` (rounded up to
// whole 8 MiB chunks of bytes that differ from chunk to chunk) written as a DirectWriter writes,
// past the page cache where the file system takes O_DIRECT (else through it, then fdatasync),
// timed until the data is on the device. Into `folder`/kWriteProbeName, which is kept and
// overwritten in place next time: removing or truncating it would make a file system mounted
// with `discard` trim its blocks just as a run starts, stalling the recorder (docs/reliability.md).
// std::runtime_error naming the file and the system's reason otherwise; a probe not written whole
// (a full disk) is removed, so that it does not take the room a run needs.
double measure_write_rate(const std::filesystem::path& folder, std::uint64_t bytes);

}  // namespace plenopiv::io
