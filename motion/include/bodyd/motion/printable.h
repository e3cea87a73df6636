// Input text as it may appear in an error message. Files and packets are untrusted: a joint
// name or a log line may hold terminal escape sequences (ESC [ ...), NUL, or megabytes without
// a line break. Every message that quotes input quotes it through printable(): printable ASCII
// is kept, every other byte is written as \xNN, and the text is cut to `max_chars` bytes of
// input with "..." after it. Pure, allocation only for the result.
#pragma once

#include <cstddef>
#include <string>
#include <string_view>

namespace bodyd {

[[nodiscard]] inline bool is_printable_ascii(unsigned char c) { return c >= 0x20 && c < 0x7f; }

// The text with non-printable bytes escaped, at most `max_chars` input bytes (then "...").
[[nodiscard]] inline std::string printable(std::string_view text, std::size_t max_chars = 40) {
  static constexpr char kHex[] = "0123456789abcdef";
  std::string out;
  out.reserve(text.size() < max_chars ? text.size() + 2 : max_chars + 5);
  for (std::size_t i = 0; i < text.size() && i < max_chars; ++i) {
    const auto c = static_cast<unsigned char>(text[i]);
    if (is_printable_ascii(c)) {
      out += static_cast<char>(c);
    } else {
      out += "\\x";
      out += kHex[c >> 4];
      out += kHex[c & 0xf];
    }
  }
  if (text.size() > max_chars) out += "...";
  return out;
}

// printable() between single quotes: 'text'.
[[nodiscard]] inline std::string quote_printable(std::string_view text, std::size_t max_chars = 40) {
  return "'" + printable(text, max_chars) + "'";
}

}  // namespace bodyd
