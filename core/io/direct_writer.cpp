// A new file written past the page cache (O_DIRECT) through aligned staging buffers.
#include "core/io/direct_writer.hpp"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <mutex>
#include <stdexcept>
#include <string>
#include <vector>

namespace plenopiv::io {

// Staging blocks per buffer: 4 MiB, so a 32 MB frame reaches the disk in eight writes.
constexpr std::size_t kStagedBlocks = 1024;

// An aligned buffer, zeroed when new. Buffers of the staging size are kept for the next file (a
// recorder writes two frames a pair for hours): a fresh 4 MiB allocation per frame would fault in
// and zero its pages each time, the very cost this writer saves. A kept one holds an old file's
// bytes; the writer zeroes only what it does not overwrite.
struct DirectWriter::Buffer {
  unsigned char* data = nullptr;
  std::size_t bytes = 0;

  static std::unique_ptr<Buffer> make(std::size_t bytes) {
    if (bytes == kStagedBlocks * kBlock) {
      std::lock_guard lock(pool_mutex());
      auto& pool = spare();
      if (!pool.empty()) {
        std::unique_ptr<Buffer> b = std::move(pool.back());
        pool.pop_back();
        return b;
      }
    }
    auto b = std::make_unique<Buffer>();
    b->data = static_cast<unsigned char*>(std::aligned_alloc(kBlock, bytes));
    if (!b->data) throw std::bad_alloc();
    b->bytes = bytes;
    std::memset(b->data, 0, bytes);
    return b;
  }
  static void give_back(std::unique_ptr<Buffer> b) {
    if (!b || b->bytes != kStagedBlocks * kBlock) return;
    std::lock_guard lock(pool_mutex());
    // Two frames of a pair are written at once; a few more spare for other writers.
    if (spare().size() < 4) spare().push_back(std::move(b));
  }
  ~Buffer() { std::free(data); }

 private:
  static std::mutex& pool_mutex() {
    static std::mutex m;
    return m;
  }
  static std::vector<std::unique_ptr<Buffer>>& spare() {
    static std::vector<std::unique_ptr<Buffer>> pool;
    return pool;
  }
};

bool DirectWriter::alignment_fits(std::uint32_t memory_align, std::uint32_t offset_align) {
  return memory_align > 0 && offset_align > 0 && kBlock % memory_align == 0 && kBlock % offset_align == 0;
}

namespace {

// Whether `fd`, opened with O_DIRECT, takes kBlock-aligned direct I/O: what the file system reports
// (Linux 6.1 and later); one that reports nothing is taken at its word that the open succeeded.
bool direct_io_fits(int fd) {
  struct statx s {};
  if (::statx(fd, "", AT_EMPTY_PATH, STATX_DIOALIGN, &s) != 0 || !(s.stx_mask & STATX_DIOALIGN)) return true;
  return DirectWriter::alignment_fits(s.stx_dio_mem_align, s.stx_dio_offset_align);
}

// Opens `path` with `flags` and O_DIRECT where the file system takes kBlock-aligned direct I/O,
// else without it (`mode` says which); -1 with errno set otherwise.
int open_direct_or_buffered(const std::filesystem::path& path, int flags, mode_t permissions, WriteMode& mode) {
  mode = WriteMode::direct;
  int fd = ::open(path.c_str(), flags | O_DIRECT, permissions);
  if (fd >= 0 && !direct_io_fits(fd)) {
    ::close(fd);
    fd = -1;
    errno = EINVAL;
  }
  if (fd < 0 && errno == EINVAL) {
    mode = WriteMode::buffered;
    fd = ::open(path.c_str(), flags, permissions);
  }
  return fd;
}

}  // namespace

DirectWriter::DirectWriter(const std::filesystem::path& path) : path_(path) {
  fd_ = open_direct_or_buffered(path, O_RDWR | O_CREAT | O_TRUNC | O_CLOEXEC, 0644, mode_);
  if (fd_ < 0) fail("cannot create");
  head_ = Buffer::make(kBlock);
  staged_ = Buffer::make(kStagedBlocks * kBlock);
}

DirectWriter::~DirectWriter() {
  Buffer::give_back(std::move(staged_));
  if (fd_ >= 0) ::close(fd_);
}

void DirectWriter::fail(const char* what) const {
  const int error = errno;
  std::string text = path_.string() + ": " + what + ": " + std::strerror(error);
  errno = error;
  throw std::runtime_error(text);
}

void DirectWriter::write_blocks(const unsigned char* data, std::size_t bytes, std::uint64_t offset) {
  while (bytes > 0) {
    const ssize_t n = ::pwrite(fd_, data, bytes, off_t(offset));
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) {
      if (n == 0) errno = EIO;
      fail("cannot write");
    }
    data += n;
    bytes -= std::size_t(n);
    offset += std::uint64_t(n);
  }
}

void DirectWriter::zero_staged_to(std::size_t end) {
  if (end > staged_filled_) std::memset(staged_->data + staged_filled_, 0, end - staged_filled_);
  staged_filled_ = std::max(staged_filled_, end);
}

void DirectWriter::flush_staged() {
  zero_staged_to(staged_->bytes);
  write_blocks(staged_->data, staged_->bytes, base_);
  base_ += staged_->bytes;
  staged_filled_ = 0;
}

// A write into a block already on the disk (libtiff does not make one for a single page, but a
// file handle allows it): read the block, patch it, write it again.
void DirectWriter::patch_flushed(const unsigned char* data, std::size_t n, std::uint64_t offset) {
  const std::unique_ptr<Buffer> block = Buffer::make(kBlock);
  while (n > 0) {
    const std::uint64_t start = offset / kBlock * kBlock;
    const std::size_t within = std::size_t(offset - start);
    const std::size_t take = std::min(n, kBlock - within);
    ssize_t got;
    do {
      got = ::pread(fd_, block->data, kBlock, off_t(start));
    } while (got < 0 && errno == EINTR);
    if (got < 0) fail("cannot read back a written block");
    std::memset(block->data + got, 0, kBlock - std::size_t(got));  // past the end: zeros
    std::memcpy(block->data + within, data, take);
    write_blocks(block->data, kBlock, start);
    data += take;
    n -= take;
    offset += take;
  }
}

void DirectWriter::write(const void* data, std::size_t n) {
  if (finished_) throw std::logic_error(path_.string() + ": written after finish()");
  const auto* bytes = static_cast<const unsigned char*>(data);
  while (n > 0) {
    std::size_t take;
    if (position_ < kBlock) {
      take = std::min<std::size_t>(n, std::size_t(kBlock - position_));
      std::memcpy(head_->data + position_, bytes, take);
    } else if (position_ < base_) {
      take = std::min<std::size_t>(n, std::size_t(base_ - position_));
      patch_flushed(bytes, take, position_);
    } else {
      while (position_ >= base_ + staged_->bytes) flush_staged();
      const std::size_t within = std::size_t(position_ - base_);
      take = std::min(n, staged_->bytes - within);
      zero_staged_to(within);  // a gap reads as zeros
      std::memcpy(staged_->data + within, bytes, take);
      staged_filled_ = std::max(staged_filled_, within + take);
    }
    bytes += take;
    n -= take;
    position_ += take;
    size_ = std::max(size_, position_);
  }
}

std::uint64_t DirectWriter::seek(std::int64_t offset, int whence) {
  const std::int64_t from = whence == SEEK_CUR ? std::int64_t(position_) : whence == SEEK_END ? std::int64_t(size_) : 0;
  if (from + offset < 0) {
    errno = EINVAL;
    fail("seek before the start");
  }
  position_ = std::uint64_t(from + offset);
  return position_;
}

void DirectWriter::finish() {
  if (finished_) throw std::logic_error(path_.string() + ": finish() twice");
  finished_ = true;
  if (size_ > base_) {
    const std::size_t end = std::size_t((size_ + kBlock - 1) / kBlock * kBlock - base_);
    zero_staged_to(end);
    write_blocks(staged_->data, end, base_);
  }
  write_blocks(head_->data, kBlock, 0);
  if (::ftruncate(fd_, off_t(size_)) != 0) fail("cannot set the file's size");
  const int fd = fd_;
  fd_ = -1;
  if (::close(fd) != 0) fail("cannot close");
}

WriteMode direct_write_mode(const std::filesystem::path& folder) {
  const std::filesystem::path probe = folder / (".direct-write-probe-" + std::to_string(::getpid()));
  const int fd = ::open(probe.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_DIRECT | O_CLOEXEC, 0600);
  const int error = errno;
  ::unlink(probe.c_str());
  if (fd >= 0) {
    const bool fits = direct_io_fits(fd);
    ::close(fd);
    return fits ? WriteMode::direct : WriteMode::buffered;
  }
  if (error == EINVAL) return WriteMode::buffered;
  throw std::runtime_error(folder.string() + ": cannot make a file: " + std::strerror(error));
}

double measure_write_rate(const std::filesystem::path& folder, std::uint64_t bytes) {
  const std::filesystem::path path = folder / kWriteProbeName;
  const auto fail = [&](const char* what, int error) {
    throw std::runtime_error(path.string() + ": " + what + ": " + std::strerror(error));
  };
  // A probe that could not be written whole is removed: left, it could fill the disk a run needs.
  const auto fail_and_remove = [&](int fd, const char* what, int error) {
    ::close(fd);
    ::unlink(path.c_str());
    fail(what, error);
  };
  WriteMode mode;  // buffered: the fdatasync below still times the data to the device
  // No O_TRUNC: the blocks stay allocated.
  const int fd = open_direct_or_buffered(path, O_WRONLY | O_CREAT | O_CLOEXEC, 0600, mode);
  if (fd < 0) fail("cannot open the write probe", errno);
  constexpr std::size_t kChunk = std::size_t(8) << 20;
  const std::uint64_t chunks = std::max<std::uint64_t>(1, (bytes + kChunk - 1) / kChunk);
  const std::unique_ptr<std::uint64_t, decltype(&std::free)> buffer(
      static_cast<std::uint64_t*>(std::aligned_alloc(DirectWriter::kBlock, kChunk)), &std::free);
  if (!buffer) {
    ::close(fd);
    throw std::bad_alloc();
  }
  // Bytes like a frame's, not zeros a file system or device might compress or skip (xorshift64).
  std::uint64_t state = 0x9e3779b97f4a7c15ull;
  for (std::size_t i = 0; i < kChunk / sizeof(std::uint64_t); ++i) {
    state ^= state << 13;
    state ^= state >> 7;
    state ^= state << 17;
    buffer.get()[i] = state;
  }
  const auto t0 = std::chrono::steady_clock::now();
  for (std::uint64_t c = 0; c < chunks; ++c) {
    buffer.get()[0] = c;  // every chunk different
    const auto* data = reinterpret_cast<const unsigned char*>(buffer.get());
    for (std::size_t done = 0; done < kChunk;) {
      const ssize_t n = ::pwrite(fd, data + done, kChunk - done, off_t(c * kChunk + done));
      if (n < 0 && errno == EINTR) continue;
      if (n <= 0) fail_and_remove(fd, "cannot write the write probe", n < 0 ? errno : EIO);
      done += std::size_t(n);
    }
  }
  if (::fdatasync(fd) != 0) fail_and_remove(fd, "cannot sync the write probe", errno);
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  ::close(fd);
  return double(chunks * kChunk) / std::max(seconds, 1e-9);
}

}  // namespace plenopiv::io
