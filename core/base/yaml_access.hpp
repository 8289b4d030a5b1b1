// Typed access to YAML config files with messages that name the file, the key and the reason.
#pragma once

#include <yaml-cpp/yaml.h>

#include <cstddef>
#include <filesystem>
#include <initializer_list>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <utility>

namespace plenopiv {

// Limits on every YAML document plenopiv reads (configs, camera files, requests): the largest
// text, the deepest nesting and the most nodes with aliases expanded. Real configs are a few KiB
// and a few levels deep; the limits keep a hostile or mistaken document from taking the memory or
// the time of whoever reads it.
inline constexpr std::size_t kMaxYamlBytes = 1024 * 1024;
inline constexpr int kMaxYamlDepth = 32;
inline constexpr std::size_t kMaxYamlNodes = 100'000;

// Parses a YAML file; an unreadable file, one over kMaxYamlBytes, a syntax error or a document
// beyond the limits is an InputError naming the file.
YAML::Node load_yaml_file(const std::filesystem::path& path);
// Parses YAML text within the same limits; `source` names it in messages.
YAML::Node load_yaml_text(const std::string& text, const std::string& source);

// A YAML mapping read key by key. Every failure throws InputError worded as
// "<source>: <dotted.key>: <reason>", e.g. "camera.yaml: microlens.pitch_mm: must be > 0, got -1".
class YamlMap {
 public:
  YamlMap(const YAML::Node& node, std::string source, std::string path = {});

  bool has(std::string_view key) const;
  YamlMap map(std::string_view key) const;
  std::optional<YamlMap> optional_map(std::string_view key) const;

  double number(std::string_view key) const;
  double number_or(std::string_view key, double fallback) const;
  long long integer(std::string_view key) const;
  long long integer_or(std::string_view key, long long fallback) const;
  // A whole number from lo to hi, or `fallback` when the key is absent; "must be lo to hi, got v"
  // otherwise. The range is checked on the 64-bit value, before it narrows to int, so that a huge
  // value cannot wrap into range (4294967297 would become 1).
  int integer_in(std::string_view key, int fallback, int lo, int hi) const;
  bool boolean_or(std::string_view key, bool fallback) const;
  std::string string(std::string_view key) const;
  std::string string_or(std::string_view key, std::string fallback) const;
  // A string that must be one of `allowed`.
  std::string choice(std::string_view key, std::span<const std::string_view> allowed) const;
  std::string choice(std::string_view key, std::initializer_list<std::string_view> allowed) const {
    return choice(key, std::span<const std::string_view>(allowed.begin(), allowed.size()));
  }
  std::string choice_or(std::string_view key, std::span<const std::string_view> allowed, std::string fallback) const;
  std::string choice_or(std::string_view key, std::initializer_list<std::string_view> allowed,
                        std::string fallback) const {
    return choice_or(key, std::span<const std::string_view>(allowed.begin(), allowed.size()), std::move(fallback));
  }

  // Refuses keys not in `known` (a typo must not become a silent default).
  void reject_unknown(std::span<const std::string_view> known) const;
  void reject_unknown(std::initializer_list<std::string_view> known) const {
    reject_unknown(std::span<const std::string_view>(known.begin(), known.size()));
  }

  // "<source>: <path.key>" for messages about a key.
  std::string where(std::string_view key) const;
  [[noreturn]] void fail(std::string_view key, const std::string& reason) const;

  const YAML::Node& node() const { return node_; }
  const std::string& source() const { return source_; }
  const std::string& path() const { return path_; }

 private:
  YAML::Node required(std::string_view key) const;
  std::string key_path(std::string_view key) const;

  YAML::Node node_;
  std::string source_;
  std::string path_;
};

}  // namespace plenopiv
