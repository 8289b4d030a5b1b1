// Device URIs as run configs write them (`scheme://target?key=value&...`), parsed with clear errors.
#include "drivers/common/device_uri.hpp"

#include <cctype>
#include <charconv>
#include <cstdlib>

#include "core/base/errors.hpp"

namespace plenopiv::drivers {

namespace {

// The URI as messages quote it: bytes outside printable ASCII as \xNN.
std::string printable(const std::string& text) {
  std::string out;
  for (const unsigned char c : text) {
    if (c >= 0x20 && c < 0x7f) {
      out += char(c);
    } else {
      static const char* hex = "0123456789abcdef";
      out += {'\\', 'x', hex[c >> 4], hex[c & 15]};
    }
  }
  return out;
}

}  // namespace

DeviceUri DeviceUri::parse(std::string_view text) {
  DeviceUri uri;
  uri.text_ = std::string(text);
  for (std::size_t i = 0; i < text.size(); ++i) {
    const auto c = static_cast<unsigned char>(text[i]);
    if (c < 0x20 || c >= 0x7f) {
      uri.fail("byte " + std::to_string(i) + " is not printable ASCII (a URI is plain text)");
    }
  }
  const std::size_t sep = text.find("://");
  if (sep == std::string_view::npos) {
    uri.fail("expected <scheme>://<device>[?key=value&...]");
  }
  uri.scheme_ = std::string(text.substr(0, sep));
  if (uri.scheme_.empty()) uri.fail("the scheme before :// is empty");
  for (char c : uri.scheme_) {
    if (!std::islower(static_cast<unsigned char>(c)) && !std::isdigit(static_cast<unsigned char>(c)) && c != '-' &&
        c != '+') {
      uri.fail("scheme '" + uri.scheme_ + "' may hold only lower-case letters, digits, '-' and '+'");
    }
  }
  std::string_view rest = text.substr(sep + 3);
  const std::size_t q = rest.find('?');
  uri.target_ = std::string(rest.substr(0, q));
  for (char c : uri.target_) {
    if (std::isspace(static_cast<unsigned char>(c)) || c == '&' || c == '=') {
      uri.fail("device '" + uri.target_ + "' contains '" + std::string(1, c) + "'");
    }
  }
  if (q == std::string_view::npos) return uri;
  std::string_view query = rest.substr(q + 1);
  while (!query.empty()) {
    const std::size_t amp = query.find('&');
    const std::string_view item = query.substr(0, amp);
    query = amp == std::string_view::npos ? std::string_view{} : query.substr(amp + 1);
    if (item.empty()) continue;  // tolerate `?&a=1` and a trailing '&'
    const std::size_t eq = item.find('=');
    if (eq == std::string_view::npos || eq == 0) {
      uri.fail("parameter '" + std::string(item) + "' is not key=value");
    }
    const std::string key(item.substr(0, eq));
    if (!uri.params_.emplace(key, std::string(item.substr(eq + 1))).second) {
      uri.fail("parameter '" + key + "' is given twice");
    }
  }
  return uri;
}

bool DeviceUri::has(std::string_view key) const { return params_.count(std::string(key)) != 0; }

std::optional<std::string> DeviceUri::param(std::string_view key) const {
  auto it = params_.find(std::string(key));
  if (it == params_.end()) return std::nullopt;
  return it->second;
}

std::string DeviceUri::string_or(std::string_view key, std::string fallback) const {
  auto v = param(key);
  return v ? *v : std::move(fallback);
}

long long DeviceUri::integer(std::string_view key) const {
  auto v = param(key);
  if (!v) fail("parameter '" + std::string(key) + "' is required");
  long long out = 0;
  const char* end = v->data() + v->size();
  auto [ptr, ec] = std::from_chars(v->data(), end, out);
  if (ec != std::errc() || ptr != end) {
    fail("parameter '" + std::string(key) + "' must be an integer, got '" + *v + "'");
  }
  return out;
}

long long DeviceUri::integer_or(std::string_view key, long long fallback) const {
  return has(key) ? integer(key) : fallback;
}

double DeviceUri::number_or(std::string_view key, double fallback) const {
  auto v = param(key);
  if (!v) return fallback;
  char* end = nullptr;
  const double out = std::strtod(v->c_str(), &end);
  if (v->empty() || end != v->c_str() + v->size()) {
    fail("parameter '" + std::string(key) + "' must be a number, got '" + *v + "'");
  }
  return out;
}

void DeviceUri::reject_unknown(std::initializer_list<std::string_view> known) const {
  for (const auto& [key, value] : params_) {
    bool ok = false;
    for (std::string_view k : known) ok = ok || k == key;
    if (ok) continue;
    std::string list;
    for (std::string_view k : known) list += (list.empty() ? "" : ", ") + std::string(k);
    fail("unknown parameter '" + key + "' (known: " + (list.empty() ? "none" : list) + ")");
  }
}

void DeviceUri::fail(const std::string& reason) const {
  throw InputError("device URI '" + printable(text_) + "': " + reason);
}

}  // namespace plenopiv::drivers
