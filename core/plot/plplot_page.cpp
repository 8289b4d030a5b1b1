// One PNG page drawn with PLplot's pngcairo device: the only place core/plot starts PLplot.
#include "core/plot/plplot_page.hpp"

#include <mutex>
#include <stdexcept>
#include <string>
#include <vector>

#include "core/base/errors.hpp"
#include "core/io/atomic_file.hpp"

namespace plenopiv::plot {
namespace {

// PLplot keeps its streams in global state and is not thread-safe: every page holds this.
std::mutex& plplot_mutex() {
  static std::mutex m;
  return m;
}

// plinit asks on the terminal for a device it does not know: check first that pngcairo is there.
void require_pngcairo() {
  int count = 128;
  std::vector<const char*> menu(std::size_t(count), nullptr), names(std::size_t(count), nullptr);
  const char** menu_items = menu.data();
  const char** device_names = names.data();
  plgDevs(&menu_items, &device_names, &count);
  for (int i = 0; i < count; ++i)
    if (std::string(names[std::size_t(i)]) == "pngcairo") return;
  throw InputError("PLplot has no pngcairo device: install the Debian package plplot-driver-cairo");
}

}  // namespace

void draw_png_page(const std::filesystem::path& png, int width_px, int height_px,
                   const std::function<void(plstream&)>& draw) {
  const auto folder = png.parent_path().empty() ? std::filesystem::path(".") : png.parent_path();
  if (!std::filesystem::is_directory(folder))
    throw InputError(png.string() + ": folder " + folder.string() + " does not exist");
  std::lock_guard lock(plplot_mutex());
  require_pngcairo();
  io::write_atomically(png, [&](const std::filesystem::path& tmp) {
    {
      plstream pls;
      pls.sdev("pngcairo");
      pls.sfnam(tmp.c_str());
      pls.spage(0, 0, width_px, height_px, 0, 0);
      pls.scol0(0, 255, 255, 255);  // the paper
      pls.init();
      pls.adv(0);
      draw(pls);
    }  // plend: the PNG is written here
    if (!std::filesystem::exists(tmp) || std::filesystem::file_size(tmp) == 0)
      throw std::runtime_error(png.string() + ": PLplot wrote no image");
  });
}

}  // namespace plenopiv::plot
