// The running executable's GNU build ID: what tells results of one binary from another's.
#include <link.h>

#include <cstdio>
#include <cstring>
#include <string>

#include "core/base/build_info.hpp"

namespace plenopiv {
namespace {

// The hex digits of the NT_GNU_BUILD_ID note among the program headers of the first object
// dl_iterate_phdr reports (the executable itself); empty when it has none.
int read_build_id(struct dl_phdr_info* info, std::size_t, void* out) {
  std::string& id = *static_cast<std::string*>(out);
  for (int i = 0; i < info->dlpi_phnum; ++i) {
    const ElfW(Phdr)& ph = info->dlpi_phdr[i];
    if (ph.p_type != PT_NOTE) continue;
    const char* at = reinterpret_cast<const char*>(info->dlpi_addr + ph.p_vaddr);
    const char* end = at + ph.p_memsz;
    // A note's name and descriptor are padded to the segment's alignment (4, or 8 for some).
    const std::size_t align = ph.p_align == 8 ? 8 : 4;
    const auto padded = [align](std::size_t n) { return (n + align - 1) & ~(align - 1); };
    while (at + sizeof(ElfW(Nhdr)) <= end) {
      ElfW(Nhdr) note;
      std::memcpy(&note, at, sizeof note);
      const char* name = at + sizeof note;
      const char* desc = name + padded(note.n_namesz);
      if (note.n_type == NT_GNU_BUILD_ID && note.n_namesz == 4 && std::memcmp(name, "GNU", 4) == 0 &&
          desc + note.n_descsz <= end) {
        for (std::size_t b = 0; b < note.n_descsz; ++b) {
          char hex[3];
          std::snprintf(hex, sizeof hex, "%02x", static_cast<unsigned char>(desc[b]));
          id += hex;
        }
        return 1;
      }
      at = desc + padded(note.n_descsz);
    }
  }
  return 1;  // the executable comes first; the libraries' IDs are not its own
}

}  // namespace

const std::string& executable_build_id() {
  static const std::string id = [] {
    std::string found;
    dl_iterate_phdr(read_build_id, &found);
    return found;
  }();
  return id;
}

}  // namespace plenopiv
