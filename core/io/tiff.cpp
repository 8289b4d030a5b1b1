// Single-channel TIFF images: 8- or 16-bit in, 16-bit (or float32 stacks) out.
#include "core/io/tiff.hpp"

#include <tiffio.h>

#include <algorithm>
#include <cmath>
#include <cstdarg>
#include <cstdio>
#include <cstring>
#include <functional>
#include <memory>
#include <stdexcept>
#include <string>
#include <type_traits>

#include "core/base/errors.hpp"
#include "core/io/atomic_file.hpp"
#include "core/io/direct_writer.hpp"

namespace plenopiv::io {
namespace {

// libtiff reports through global handlers; keep its last message for our error text instead of
// letting it print to stderr.
thread_local std::string g_last_tiff_message;
void capture_handler(const char* module, const char* fmt, va_list args) {
  char buf[512];
  std::vsnprintf(buf, sizeof buf, fmt, args);
  g_last_tiff_message = std::string(module ? module : "") + ": " + buf;
}
struct QuietLibtiff {
  QuietLibtiff() {
    TIFFSetErrorHandler(capture_handler);
    TIFFSetWarningHandler(nullptr);
  }
};
const QuietLibtiff g_quiet;

struct TiffCloser {
  void operator()(TIFF* t) const { TIFFClose(t); }
};
using TiffPtr = std::unique_ptr<TIFF, TiffCloser>;

TiffPtr open(const std::filesystem::path& path, const char* mode) {
  g_last_tiff_message.clear();
  TIFF* t = TIFFOpen(path.c_str(), mode);
  if (!t) {
    throw InputError(path.string() + ": cannot open as TIFF" +
                     (g_last_tiff_message.empty() ? "" : " (" + g_last_tiff_message + ")"));
  }
  return TiffPtr(t);
}

// libtiff's client I/O onto a DirectWriter (a new file, written only). Its procedures turn the
// writer's exceptions into libtiff's failures and keep the reason for our error text.
namespace direct_tiff {
DirectWriter& writer(thandle_t h) { return *static_cast<DirectWriter*>(h); }
template <typename T, typename F>
T guarded(F&& f) {
  try {
    return f();
  } catch (const std::exception& e) {
    g_last_tiff_message = e.what();
    return T(-1);
  }
}
tmsize_t read(thandle_t, void*, tmsize_t) { return -1; }
tmsize_t write(thandle_t h, void* data, tmsize_t n) {
  return guarded<tmsize_t>([&] { return writer(h).write(data, std::size_t(n)), n; });
}
toff_t seek(thandle_t h, toff_t offset, int whence) {
  return guarded<toff_t>([&] { return toff_t(writer(h).seek(std::int64_t(offset), whence)); });
}
int close(thandle_t) { return 0; }  // the writer's owner finishes the file
toff_t size(thandle_t h) { return writer(h).size(); }
int map(thandle_t, void**, toff_t*) { return 0; }
void unmap(thandle_t, void*, toff_t) {}

TiffPtr open(DirectWriter& w, const std::filesystem::path& path) {
  g_last_tiff_message.clear();
  TIFF* t = TIFFClientOpen(path.c_str(), "w", &w, read, write, seek, close, size, map, unmap);
  if (!t) throw std::runtime_error(path.string() + ": cannot start a TIFF (" + g_last_tiff_message + ")");
  return TiffPtr(t);
}
}  // namespace direct_tiff

struct PageInfo {
  uint32_t width = 0, height = 0;
  uint16_t bits = 0, samples = 1, format = SAMPLEFORMAT_UINT;
};

PageInfo page_info(TIFF* t) {
  PageInfo p;
  TIFFGetField(t, TIFFTAG_IMAGEWIDTH, &p.width);
  TIFFGetField(t, TIFFTAG_IMAGELENGTH, &p.height);
  TIFFGetFieldDefaulted(t, TIFFTAG_BITSPERSAMPLE, &p.bits);
  TIFFGetFieldDefaulted(t, TIFFTAG_SAMPLESPERPIXEL, &p.samples);
  TIFFGetFieldDefaulted(t, TIFFTAG_SAMPLEFORMAT, &p.format);
  return p;
}

// Checks that every strip or tile of the current page lies inside the file and, for uncompressed
// data, that together they hold the pixels the header declares: a header that promises more than
// the file holds (a truncated or damaged file) is refused before any pixel buffer is allocated.
void check_pieces(TIFF* t, const std::filesystem::path& path, std::uint64_t file_size, const PageInfo& p) {
  if (p.width == 0 || p.height == 0) throw InputError(path.string() + ": TIFF has no pixels");
  const bool tiled = TIFFIsTiled(t);
  const uint32_t pieces = tiled ? TIFFNumberOfTiles(t) : TIFFNumberOfStrips(t);
  uint64_t* offsets = nullptr;
  uint64_t* counts = nullptr;
  if (!TIFFGetField(t, tiled ? TIFFTAG_TILEOFFSETS : TIFFTAG_STRIPOFFSETS, &offsets) ||
      !TIFFGetField(t, tiled ? TIFFTAG_TILEBYTECOUNTS : TIFFTAG_STRIPBYTECOUNTS, &counts) || !offsets || !counts) {
    throw InputError(path.string() + ": corrupt TIFF: no strip or tile table");
  }
  uint64_t stored = 0;
  for (uint32_t i = 0; i < pieces; ++i) {
    if (counts[i] > file_size || offsets[i] > file_size - counts[i]) {
      throw InputError(path.string() + ": truncated or corrupt TIFF: " + (tiled ? "tile " : "strip ") +
                       std::to_string(i) + " ends at byte " + std::to_string(offsets[i] + counts[i]) +
                       ", the file has " + std::to_string(file_size));
    }
    stored += counts[i];
  }
  uint16_t compression = COMPRESSION_NONE;
  TIFFGetFieldDefaulted(t, TIFFTAG_COMPRESSION, &compression);
  const double declared = double(p.width) * double(p.height) * double(p.samples) * double(p.bits) / 8.0;
  if (compression == COMPRESSION_NONE && double(stored) < declared) {
    throw InputError(path.string() + ": truncated or corrupt TIFF: its header declares " + std::to_string(p.width) +
                     " x " + std::to_string(p.height) + " px (" + std::to_string(std::uint64_t(declared)) +
                     " bytes), its strips hold " + std::to_string(stored) + " bytes");
  }
  // Compressed strips expand at most ~64x (PackBits), ~1032x (deflate), ~2700x (LZW's 12-bit codes
  // for strings of up to 4096 bytes): a header that declares more is damage or a decompression bomb.
  constexpr double kMaxExpansion = 4096;
  if (compression != COMPRESSION_NONE && declared > double(stored) * kMaxExpansion) {
    throw InputError(path.string() + ": corrupt TIFF: its header declares " + std::to_string(p.width) + " x " +
                     std::to_string(p.height) + " px (" + std::to_string(std::uint64_t(declared)) +
                     " bytes), more than its " + std::to_string(stored) + " compressed bytes can hold");
  }
}

std::uint64_t file_size_of(const std::filesystem::path& path) {
  std::error_code ec;
  const auto size = std::filesystem::file_size(path, ec);
  if (ec) throw InputError(path.string() + ": cannot read: " + ec.message());
  return size;
}

void read_rows(TIFF* t, const std::filesystem::path& path, uint32_t height, void* row_buffer,
               const std::function<void(uint32_t)>& use_row) {
  for (uint32_t y = 0; y < height; ++y) {
    if (TIFFReadScanline(t, row_buffer, y, 0) < 0) {
      throw InputError(path.string() + ": corrupt TIFF: row " + std::to_string(y) + " cannot be read (" +
                       g_last_tiff_message + ")");
    }
    use_row(y);
  }
}

void set_page_fields(TIFF* t, int width, int height, uint16_t bits, uint16_t format) {
  TIFFSetField(t, TIFFTAG_IMAGEWIDTH, uint32_t(width));
  TIFFSetField(t, TIFFTAG_IMAGELENGTH, uint32_t(height));
  TIFFSetField(t, TIFFTAG_SAMPLESPERPIXEL, uint16_t(1));
  TIFFSetField(t, TIFFTAG_BITSPERSAMPLE, bits);
  TIFFSetField(t, TIFFTAG_SAMPLEFORMAT, format);
  TIFFSetField(t, TIFFTAG_PHOTOMETRIC, PHOTOMETRIC_MINISBLACK);
  TIFFSetField(t, TIFFTAG_PLANARCONFIG, PLANARCONFIG_CONTIG);
  TIFFSetField(t, TIFFTAG_COMPRESSION, COMPRESSION_NONE);
  TIFFSetField(t, TIFFTAG_ROWSPERSTRIP, uint32_t(std::max(1, 65536 / std::max(1, width * bits / 8))));
}

// Write failures are the disk's, not the input's: std::runtime_error (write_atomically names a
// full disk).
void write_row(TIFF* t, const std::filesystem::path& path, const void* row, int y) {
  if (TIFFWriteScanline(t, const_cast<void*>(row), uint32_t(y), 0) < 0) {
    throw std::runtime_error(path.string() + ": cannot write TIFF row " + std::to_string(y) + " (" +
                             g_last_tiff_message + ")");
  }
}

// Uncompressed 16-bit pixels in the host's byte order, which is the file's, are their own
// encoding: each strip goes to the writer straight from the image, without libtiff's copy into its
// strip buffer (a recorder writes two camera frames per pair).
void write_raw_strips(TIFF* t, const std::filesystem::path& path, const ImageU16& image,
                      const RowsVisitor& visit_rows) {
  uint32_t rows_per_strip = 0;
  TIFFGetFieldDefaulted(t, TIFFTAG_ROWSPERSTRIP, &rows_per_strip);
  if (rows_per_strip == 0) rows_per_strip = 1;
  const tstrip_t strips = TIFFNumberOfStrips(t);
  for (tstrip_t strip = 0; strip < strips; ++strip) {
    const int y0 = int(strip * rows_per_strip);
    const int rows = std::min(int(rows_per_strip), image.height - y0);
    const tmsize_t bytes = tmsize_t(rows) * image.width * tmsize_t(sizeof(std::uint16_t));
    if (visit_rows) visit_rows(std::span<const std::uint16_t>(image.row(y0).data(), std::size_t(rows) * image.width));
    if (TIFFWriteRawStrip(t, strip, const_cast<std::uint16_t*>(image.row(y0).data()), bytes) != bytes) {
      throw std::runtime_error(path.string() + ": cannot write TIFF rows " + std::to_string(y0) + " to " +
                               std::to_string(y0 + rows - 1) + " (" + g_last_tiff_message + ")");
    }
  }
}

// Writes what libtiff still buffers; TIFFClose alone would lose a failure there.
void flush(TIFF* t, const std::filesystem::path& path) {
  if (!TIFFFlush(t)) throw std::runtime_error(path.string() + ": cannot write TIFF (" + g_last_tiff_message + ")");
}

}  // namespace

ImageU16 read_tiff_u16(const std::filesystem::path& path) {
  ImageU16 image;
  read_tiff_u16(path, image);
  return image;
}

void read_tiff_u16(const std::filesystem::path& path, ImageU16& image) {
  TiffPtr t = open(path, "r");
  const std::uint64_t file_size = file_size_of(path);
  const PageInfo p = page_info(t.get());
  if (p.samples != 1 || (p.bits != 8 && p.bits != 16) || p.format != SAMPLEFORMAT_UINT) {
    throw InputError(path.string() + ": expected a single-channel 8- or 16-bit unsigned TIFF, got " +
                     std::to_string(p.samples) + " channel(s) of " + std::to_string(p.bits) + "-bit " +
                     (p.format == SAMPLEFORMAT_IEEEFP ? "float" : "integer") + " samples");
  }
  check_pieces(t.get(), path, file_size, p);
  if (image.width != int(p.width) || image.height != int(p.height)) image = ImageU16(int(p.width), int(p.height));
  std::vector<unsigned char> row(TIFFScanlineSize(t.get()));
  read_rows(t.get(), path, p.height, row.data(), [&](uint32_t y) {
    auto out = image.row(int(y));
    if (p.bits == 16) {
      std::memcpy(out.data(), row.data(), out.size() * sizeof(uint16_t));
    } else {
      for (uint32_t x = 0; x < p.width; ++x) out[x] = row[x];
    }
  });
}

ImageF read_tiff_float(const std::filesystem::path& path) {
  TiffPtr t = open(path, "r");
  const PageInfo p = page_info(t.get());
  const bool uint = p.format == SAMPLEFORMAT_UINT && (p.bits == 8 || p.bits == 16);
  const bool fp = p.format == SAMPLEFORMAT_IEEEFP && (p.bits == 32 || p.bits == 64);
  if (p.samples != 1 || !(uint || fp)) {
    throw InputError(path.string() +
                     ": expected a single-channel TIFF of 8- or 16-bit unsigned or 32/64-bit float "
                     "samples, got " +
                     std::to_string(p.samples) + " channel(s) of " + std::to_string(p.bits) + "-bit " +
                     (p.format == SAMPLEFORMAT_IEEEFP ? "float"
                      : p.format == SAMPLEFORMAT_INT  ? "signed"
                                                      : "unsigned") +
                     " samples");
  }
  if (p.width == 0 || p.height == 0) throw InputError(path.string() + ": TIFF has no pixels");
  ImageF image(int(p.width), int(p.height));
  std::vector<unsigned char> row(TIFFScanlineSize(t.get()));
  if (row.size() < std::size_t(p.width) * (p.bits / 8)) throw InputError(path.string() + ": corrupt TIFF (short rows)");
  // One loop per sample type (the compiler vectorises the integer ones); counts are finite by
  // their type, so only float samples are checked.
  const auto convert = [&](uint32_t y, auto sample) {
    using T = decltype(sample);
    float* out = image.row(int(y)).data();
    for (uint32_t x = 0; x < p.width; ++x) {
      T v;
      std::memcpy(&v, row.data() + sizeof(T) * x, sizeof(T));
      if constexpr (std::is_floating_point_v<T>) {
        if (!std::isfinite(v) || std::abs(double(v)) > 3.0e38) {
          throw InputError(path.string() + ": pixel (" + std::to_string(x) + ", " + std::to_string(y) + ") is " +
                           std::to_string(v) + "; a raw frame's values must be finite");
        }
      }
      out[x] = float(v);
    }
  };
  read_rows(t.get(), path, p.height, row.data(), [&](uint32_t y) {
    switch (p.bits) {
      case 8:
        return convert(y, std::uint8_t{});
      case 16:
        return convert(y, std::uint16_t{});
      case 32:
        return convert(y, float{});
      default:
        return convert(y, double{});
    }
  });
  return image;
}

void write_tiff(const std::filesystem::path& path, const ImageU16& image, bool sync_folder,
                const RowsVisitor& visit_rows) {
  write_atomically(
      path,
      [&](const std::filesystem::path& tmp) {
        DirectWriter file(tmp);
        TiffPtr t = direct_tiff::open(file, tmp);
        set_page_fields(t.get(), image.width, image.height, 16, SAMPLEFORMAT_UINT);
        write_raw_strips(t.get(), path, image, visit_rows);
        flush(t.get(), path);
        t.reset();
        file.finish();
      },
      sync_folder);
}

void write_tiff_stack(const std::filesystem::path& path, const std::vector<ImageF>& pages,
                      const std::vector<std::string>& descriptions) {
  if (!descriptions.empty() && descriptions.size() != pages.size()) {
    throw std::logic_error("write_tiff_stack: " + std::to_string(descriptions.size()) + " descriptions for " +
                           std::to_string(pages.size()) + " pages");
  }
  write_atomically(path, [&](const std::filesystem::path& tmp) {
    TiffPtr t = open(tmp, "w");
    for (std::size_t i = 0; i < pages.size(); ++i) {
      const ImageF& page = pages[i];
      set_page_fields(t.get(), page.width, page.height, 32, SAMPLEFORMAT_IEEEFP);
      TIFFSetField(t.get(), TIFFTAG_SUBFILETYPE, FILETYPE_PAGE);
      TIFFSetField(t.get(), TIFFTAG_PAGENUMBER, uint16_t(i), uint16_t(pages.size()));
      if (!descriptions.empty()) TIFFSetField(t.get(), TIFFTAG_IMAGEDESCRIPTION, descriptions[i].c_str());
      for (int y = 0; y < page.height; ++y) write_row(t.get(), path, page.row(y).data(), y);
      if (!TIFFWriteDirectory(t.get())) {
        throw std::runtime_error(path.string() + ": cannot write TIFF page " + std::to_string(i));
      }
    }
    flush(t.get(), path);
  });
}

std::vector<ImageF> read_tiff_stack(const std::filesystem::path& path) {
  TiffPtr t = open(path, "r");
  const std::uint64_t file_size = file_size_of(path);
  std::vector<ImageF> pages;
  do {
    const PageInfo p = page_info(t.get());
    const bool f32 = p.bits == 32 && p.format == SAMPLEFORMAT_IEEEFP;
    const bool u16 = p.bits == 16 && p.format == SAMPLEFORMAT_UINT;
    if (p.samples != 1 || !(f32 || u16)) {
      throw InputError(path.string() + ": page " + std::to_string(pages.size()) +
                       ": expected single-channel float32 or uint16 samples");
    }
    check_pieces(t.get(), path, file_size, p);
    ImageF page(int(p.width), int(p.height));
    std::vector<unsigned char> row(TIFFScanlineSize(t.get()));
    read_rows(t.get(), path, p.height, row.data(), [&](uint32_t y) {
      auto out = page.row(int(y));
      for (uint32_t x = 0; x < p.width; ++x) {
        if (f32) {
          std::memcpy(&out[x], row.data() + 4 * x, 4);
        } else {
          uint16_t v;
          std::memcpy(&v, row.data() + 2 * x, 2);
          out[x] = v;
        }
      }
    });
    pages.push_back(std::move(page));
  } while (TIFFReadDirectory(t.get()));
  return pages;
}

std::vector<std::string> read_tiff_descriptions(const std::filesystem::path& path) {
  TiffPtr t = open(path, "r");
  std::vector<std::string> out;
  do {
    const char* text = nullptr;
    out.emplace_back(TIFFGetField(t.get(), TIFFTAG_IMAGEDESCRIPTION, &text) == 1 && text ? text : "");
  } while (TIFFReadDirectory(t.get()));
  return out;
}

TiffInfo check_tiff(const std::filesystem::path& path) {
  const std::uint64_t file_size = file_size_of(path);
  TiffPtr t = open(path, "r");
  const PageInfo p = page_info(t.get());
  check_pieces(t.get(), path, file_size, p);
  return {int(p.width), int(p.height), int(p.bits)};
}

}  // namespace plenopiv::io
