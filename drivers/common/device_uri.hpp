// Device URIs as run configs write them (`scheme://target?key=value&...`), parsed with clear errors.
#pragma once

#include <initializer_list>
#include <map>
#include <optional>
#include <string>
#include <string_view>

namespace plenopiv::drivers {

// `aravis://192.168.1.20?profile=jai-piv`, `sim://?seed=1`, `gpiod://gpiochip0?camera=27`.
// Every failure is an InputError that quotes the whole URI and says what is wrong with it.
class DeviceUri {
 public:
  static DeviceUri parse(std::string_view text);

  const std::string& text() const { return text_; }
  const std::string& scheme() const { return scheme_; }
  const std::string& target() const { return target_; }  // device id, address or chip; may be empty
  const std::map<std::string, std::string>& params() const { return params_; }

  bool has(std::string_view key) const;
  std::optional<std::string> param(std::string_view key) const;
  std::string string_or(std::string_view key, std::string fallback) const;
  long long integer_or(std::string_view key, long long fallback) const;
  long long integer(std::string_view key) const;  // required
  double number_or(std::string_view key, double fallback) const;
  // Refuses parameters not in `known`: a typo must not become a silent default.
  void reject_unknown(std::initializer_list<std::string_view> known) const;

  [[noreturn]] void fail(const std::string& reason) const;

 private:
  std::string text_, scheme_, target_;
  std::map<std::string, std::string> params_;
};

}  // namespace plenopiv::drivers
