// File contents and their CRC-32 (zlib): how a run folder says which bytes of a file it copied.
#pragma once

#include <cstdint>
#include <filesystem>
#include <string>
#include <string_view>

namespace plenopiv::io {

// The whole file as bytes; InputError naming the file when it is missing or cannot be read.
std::string read_file_bytes(const std::filesystem::path& path);
// A file's bytes mapped read-only, for reading a large file once without copying it or zeroing a
// buffer for it first; InputError naming the file when it is missing or cannot be mapped. The bytes
// are valid while the object lives. A file must not be truncated in place while mapped (reading
// past its new end is a SIGBUS); one replaced by a rename (io::write_atomically) or removed is safe:
// the mapping keeps the old file's bytes.
class MappedFile {
 public:
  explicit MappedFile(const std::filesystem::path& path);
  ~MappedFile();
  MappedFile(const MappedFile&) = delete;
  MappedFile& operator=(const MappedFile&) = delete;
  std::string_view bytes() const { return {static_cast<const char*>(data_), size_}; }

 private:
  void* data_ = nullptr;
  std::size_t size_ = 0;
};
// CRC-32 (zlib's, as `crc32` in Python's zlib and binascii) of `bytes`.
std::uint32_t crc32_of(std::string_view bytes);
// CRC-32 of a file's bytes and their count, read in pieces (the file is never whole in memory);
// InputError naming the file when it is missing or cannot be read.
struct FileChecksum {
  std::uint32_t crc32 = 0;
  std::uint64_t bytes = 0;
};
FileChecksum checksum_of_file(const std::filesystem::path& path);
// "%08x" of a CRC-32, as manifests write it.
std::string crc32_hex(std::uint32_t crc);

}  // namespace plenopiv::io
