// An owned HDF5 identifier, and HDF5's error printing turned off: shared by plenopiv's HDF5 files.
#pragma once

#include <hdf5.h>

namespace plenopiv::io {

// Owns one HDF5 identifier and closes it with the matching call (H5Fclose, H5Dclose, ...).
class Hdf5Handle {
 public:
  Hdf5Handle(hid_t id, herr_t (*close)(hid_t)) : id_(id), close_(close) {}
  ~Hdf5Handle() {
    if (id_ >= 0) close_(id_);
  }
  Hdf5Handle(Hdf5Handle&& other) noexcept : id_(other.id_), close_(other.close_) { other.id_ = -1; }
  Hdf5Handle(const Hdf5Handle&) = delete;
  Hdf5Handle& operator=(const Hdf5Handle&) = delete;
  hid_t get() const { return id_; }
  bool ok() const { return id_ >= 0; }

 private:
  hid_t id_;
  herr_t (*close_)(hid_t);
};

// HDF5 prints its error stack to stderr by default; plenopiv reports through InputError instead.
// Done once per program, before main, by this inline variable (one instance however many files
// include the header).
struct Hdf5ErrorsSilenced {
  Hdf5ErrorsSilenced() { H5Eset_auto2(H5E_DEFAULT, nullptr, nullptr); }
};
inline const Hdf5ErrorsSilenced hdf5_errors_silenced{};

}  // namespace plenopiv::io
