// What built this binary: the project's version and the source's git commit, for provenance.
#pragma once

#include <string>
#include <string_view>

namespace plenopiv {

std::string_view build_version();  // the CMake project version, e.g. "0.1.0"
// `git describe --always --dirty` of the source tree at build time ("-dirty": uncommitted changes;
// "unknown": built outside a git checkout).
std::string_view build_commit();
// The running executable's GNU build ID (the linker's hash of its contents) in hex; empty when it
// was linked without one. What a cache of computed results keys the code on: any change of code,
// committed or not, gives another ID.
const std::string& executable_build_id();

}  // namespace plenopiv
