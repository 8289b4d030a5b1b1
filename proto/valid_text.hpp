// Text fields made valid UTF-8 before a message leaves the daemon: proto3 string fields must be
// UTF-8, and a reader refuses a message with one that is not.
#pragma once

#include <google/protobuf/message.h>

#include <string>
#include <string_view>

namespace plenopiv::msg {

// `text` with every byte that does not belong to a well-formed UTF-8 sequence (RFC 3629: no
// overlong forms, no surrogates, nothing above U+10FFFF) replaced by U+FFFD; well-formed text is
// returned unchanged.
std::string valid_utf8(std::string_view text);

// Applies valid_utf8 to every string field (not bytes fields) of `message` and of the messages it
// holds, so that an error text quoting a user's bytes or a device's name cannot make the message
// unreadable. Returns the number of fields changed.
int make_text_valid_utf8(google::protobuf::Message& message);

}  // namespace plenopiv::msg
