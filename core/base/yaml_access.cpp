// Typed access to YAML config files with messages that name the file, the key and the reason.
#include "core/base/yaml_access.hpp"

#include <cmath>
#include <fstream>
#include <sstream>

#include "core/base/errors.hpp"

namespace plenopiv {
namespace {

std::string line_of(const YAML::Node& node) {
  const YAML::Mark mark = node.Mark();
  if (mark.line < 0) return {};
  return " (line " + std::to_string(mark.line + 1) + ")";
}

std::string scalar_text(const YAML::Node& node) {
  if (node.IsScalar()) return "'" + node.Scalar() + "'";
  if (node.IsMap()) return "a mapping";
  if (node.IsSequence()) return "a list";
  return "nothing";
}

// The unit a key carries in its name (pitch_mm, width_px, dt_s), for error messages.
std::string unit_hint(std::string_view key) {
  auto ends = [&](std::string_view suffix) {
    return key.size() > suffix.size() && key.substr(key.size() - suffix.size()) == suffix;
  };
  if (ends("_mm")) return " in millimetres";
  if (ends("_px")) return " in pixels";
  if (ends("_s")) return " in seconds";
  if (ends("_um")) return " in micrometres";
  return {};
}

// Walks the document as readers will (aliases expanded), refusing more than kMaxYamlDepth levels
// or kMaxYamlNodes nodes: a few lines of nested aliases can stand for billions of nodes.
void check_yaml_shape(const YAML::Node& node, int depth, std::size_t& visited, const std::string& source) {
  if (++visited > kMaxYamlNodes) {
    throw InputError(source + ": more than " + std::to_string(kMaxYamlNodes) +
                     " YAML nodes (aliases expanded): not a plenopiv config");
  }
  if (depth > kMaxYamlDepth) {
    throw InputError(source + ": nested deeper than " + std::to_string(kMaxYamlDepth) + " levels" + line_of(node) +
                     ": not a plenopiv config");
  }
  if (node.IsSequence()) {
    for (const YAML::Node& item : node) check_yaml_shape(item, depth + 1, visited, source);
  } else if (node.IsMap()) {
    for (const auto& item : node) {
      check_yaml_shape(item.first, depth + 1, visited, source);
      check_yaml_shape(item.second, depth + 1, visited, source);
    }
  }
}

}  // namespace

YAML::Node load_yaml_file(const std::filesystem::path& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw InputError(path.string() + ": cannot open file for reading");
  // At most one byte more than a config may have: a device or an endless pipe is not read to the end.
  std::string text(kMaxYamlBytes + 1, '\0');
  in.read(text.data(), std::streamsize(text.size()));
  if (in.bad()) throw InputError(path.string() + ": cannot read the file");
  text.resize(std::size_t(in.gcount()));
  return load_yaml_text(text, path.string());
}

YAML::Node load_yaml_text(const std::string& text, const std::string& source) {
  if (text.size() > kMaxYamlBytes) {
    throw InputError(source + ": larger than " + std::to_string(kMaxYamlBytes / 1024) + " KiB: not a plenopiv config");
  }
  try {
    YAML::Node root = YAML::Load(text);
    if (!root.IsMap()) throw InputError(source + ": expected a YAML mapping at the top level");
    std::size_t visited = 0;
    check_yaml_shape(root, 0, visited, source);
    return root;
  } catch (const YAML::Exception& e) {
    throw InputError(source + ": not valid YAML: " + e.msg + " (line " + std::to_string(e.mark.line + 1) + ")");
  }
}

YamlMap::YamlMap(const YAML::Node& node, std::string source, std::string path)
    : node_(node), source_(std::move(source)), path_(std::move(path)) {
  if (!node_.IsMap()) {
    throw InputError(source_ + ": " + (path_.empty() ? std::string("top level") : path_) +
                     ": expected a mapping of keys, got " + scalar_text(node_) + line_of(node_));
  }
}

std::string YamlMap::key_path(std::string_view key) const {
  return path_.empty() ? std::string(key) : path_ + "." + std::string(key);
}

std::string YamlMap::where(std::string_view key) const { return source_ + ": " + key_path(key); }

void YamlMap::fail(std::string_view key, const std::string& reason) const {
  const YAML::Node child = node_[std::string(key)];
  throw InputError(where(key) + ": " + reason + (child ? line_of(child) : std::string{}));
}

bool YamlMap::has(std::string_view key) const {
  const YAML::Node child = node_[std::string(key)];
  return child && !child.IsNull();
}

YAML::Node YamlMap::required(std::string_view key) const {
  const YAML::Node child = node_[std::string(key)];
  if (!child || child.IsNull()) {
    throw InputError(where(key) + ": missing (required key)" + line_of(node_));
  }
  return child;
}

YamlMap YamlMap::map(std::string_view key) const { return YamlMap(required(key), source_, key_path(key)); }

std::optional<YamlMap> YamlMap::optional_map(std::string_view key) const {
  if (!has(key)) return std::nullopt;
  return map(key);
}

double YamlMap::number(std::string_view key) const {
  const YAML::Node child = required(key);
  double value = 0;
  if (!child.IsScalar() || !YAML::convert<double>::decode(child, value)) {
    fail(key, "expected a number" + unit_hint(key) + ", got " + scalar_text(child));
  }
  if (!std::isfinite(value)) fail(key, "expected a finite number, got " + scalar_text(child));
  return value;
}

double YamlMap::number_or(std::string_view key, double fallback) const { return has(key) ? number(key) : fallback; }

long long YamlMap::integer(std::string_view key) const {
  const YAML::Node child = required(key);
  long long value = 0;
  if (!child.IsScalar() || !YAML::convert<long long>::decode(child, value)) {
    fail(key, "expected a whole number" + unit_hint(key) + ", got " + scalar_text(child));
  }
  return value;
}

long long YamlMap::integer_or(std::string_view key, long long fallback) const {
  return has(key) ? integer(key) : fallback;
}

int YamlMap::integer_in(std::string_view key, int fallback, int lo, int hi) const {
  const long long value = integer_or(key, fallback);
  if (value < lo || value > hi) {
    fail(key, "must be " + std::to_string(lo) + " to " + std::to_string(hi) + ", got " + std::to_string(value));
  }
  return int(value);
}

bool YamlMap::boolean_or(std::string_view key, bool fallback) const {
  if (!has(key)) return fallback;
  const YAML::Node child = required(key);
  bool value = false;
  if (!child.IsScalar() || !YAML::convert<bool>::decode(child, value)) {
    fail(key, "expected true or false, got " + scalar_text(child));
  }
  return value;
}

std::string YamlMap::string(std::string_view key) const {
  const YAML::Node child = required(key);
  if (!child.IsScalar()) fail(key, "expected a text value, got " + scalar_text(child));
  return child.Scalar();
}

std::string YamlMap::string_or(std::string_view key, std::string fallback) const {
  return has(key) ? string(key) : fallback;
}

std::string YamlMap::choice(std::string_view key, std::span<const std::string_view> allowed) const {
  const std::string value = string(key);
  std::string list;
  for (std::string_view a : allowed) {
    if (a == value) return value;
    list += (list.empty() ? "" : ", ") + std::string(a);
  }
  fail(key, "expected one of " + list + ", got '" + value + "'");
}

std::string YamlMap::choice_or(std::string_view key, std::span<const std::string_view> allowed,
                               std::string fallback) const {
  return has(key) ? choice(key, allowed) : fallback;
}

void YamlMap::reject_unknown(std::span<const std::string_view> known) const {
  for (const auto& entry : node_) {
    if (!entry.first.IsScalar()) {
      throw InputError(source_ + ": " + (path_.empty() ? std::string("top level") : path_) + ": a key that is " +
                       scalar_text(entry.first) + ", not a name" + line_of(entry.first));
    }
    const std::string name = entry.first.Scalar();
    bool found = false;
    std::string list;
    for (std::string_view k : known) {
      found = found || k == name;
      list += (list.empty() ? "" : ", ") + std::string(k);
    }
    if (!found) {
      throw InputError(where(name) + ": unknown key (known keys here: " + list + ")" + line_of(entry.first));
    }
  }
}

}  // namespace plenopiv
