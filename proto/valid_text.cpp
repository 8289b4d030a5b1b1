// Text fields made valid UTF-8 before a message leaves the daemon.
#include "proto/valid_text.hpp"

#include <cstdint>
#include <vector>

namespace plenopiv::msg {
namespace {

// Length of the well-formed UTF-8 sequence at the start of `s`, or 0 if it does not start with one
// (the table of well-formed byte sequences in the Unicode Standard, section 3.9).
std::size_t sequence_length(std::string_view s) {
  const auto byte = [&](std::size_t i) { return std::uint8_t(s[i]); };
  const auto continuation = [&](std::size_t i, std::uint8_t lo = 0x80, std::uint8_t hi = 0xBF) {
    return i < s.size() && byte(i) >= lo && byte(i) <= hi;
  };
  const std::uint8_t b0 = byte(0);
  if (b0 < 0x80) return 1;
  if (b0 >= 0xC2 && b0 <= 0xDF) return continuation(1) ? 2 : 0;
  if (b0 >= 0xE0 && b0 <= 0xEF) {
    const std::uint8_t lo = b0 == 0xE0 ? 0xA0 : 0x80;  // no overlong forms
    const std::uint8_t hi = b0 == 0xED ? 0x9F : 0xBF;  // no surrogates
    return continuation(1, lo, hi) && continuation(2) ? 3 : 0;
  }
  if (b0 >= 0xF0 && b0 <= 0xF4) {
    const std::uint8_t lo = b0 == 0xF0 ? 0x90 : 0x80;  // no overlong forms
    const std::uint8_t hi = b0 == 0xF4 ? 0x8F : 0xBF;  // nothing above U+10FFFF
    return continuation(1, lo, hi) && continuation(2) && continuation(3) ? 4 : 0;
  }
  return 0;
}

bool is_valid_utf8(std::string_view text) {
  for (std::size_t i = 0; i < text.size();) {
    const std::size_t n = sequence_length(text.substr(i));
    if (n == 0) return false;
    i += n;
  }
  return true;
}

}  // namespace

std::string valid_utf8(std::string_view text) {
  std::string out;
  out.reserve(text.size());
  for (std::size_t i = 0; i < text.size();) {
    const std::size_t n = sequence_length(text.substr(i));
    if (n == 0) {
      out += "\xEF\xBF\xBD";
      ++i;
    } else {
      out.append(text.substr(i, n));
      i += n;
    }
  }
  return out;
}

int make_text_valid_utf8(google::protobuf::Message& message) {
  using google::protobuf::FieldDescriptor;
  const google::protobuf::Reflection* reflection = message.GetReflection();
  int changed = 0;
  const auto mend = [&](const std::string& text, auto&& set) {
    if (is_valid_utf8(text)) return;
    set(valid_utf8(text));
    ++changed;
  };
  std::vector<const FieldDescriptor*> fields;
  reflection->ListFields(message, &fields);
  for (const FieldDescriptor* field : fields) {
    if (field->type() == FieldDescriptor::TYPE_STRING) {
      if (field->is_repeated()) {
        for (int i = 0; i < reflection->FieldSize(message, field); ++i) {
          mend(reflection->GetRepeatedString(message, field, i),
               [&](std::string v) { reflection->SetRepeatedString(&message, field, i, std::move(v)); });
        }
      } else {
        mend(reflection->GetString(message, field),
             [&](std::string v) { reflection->SetString(&message, field, std::move(v)); });
      }
    } else if (field->cpp_type() == FieldDescriptor::CPPTYPE_MESSAGE) {
      if (field->is_repeated()) {
        for (int i = 0; i < reflection->FieldSize(message, field); ++i) {
          changed += make_text_valid_utf8(*reflection->MutableRepeatedMessage(&message, field, i));
        }
      } else {
        changed += make_text_valid_utf8(*reflection->MutableMessage(&message, field));
      }
    }
  }
  return changed;
}

}  // namespace plenopiv::msg
