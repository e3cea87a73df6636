// The bug check (docs/architecture.md, "Errors"): a broken invariant or precondition is a bug in
// bodyd, never something a user can fix, so it stops the process loudly in every build type
// (release too, unlike assert). A failure the user can fix returns an error instead; an expected
// non-event is a value.
//
//   BODYD_REQUIRE(batch >= 1, "batch must be >= 1");
//   BODYD_REQUIRE(s.ok(), "the pose cannot be encoded: " + s.error);   // built only on failure
//
// On failure it prints "FILE:LINE: bug: WHAT (CONDITION)" to stderr and calls std::abort().
#pragma once

#include <string_view>

namespace bodyd::detail {
[[noreturn]] void require_failed(const char* file, int line, const char* condition, std::string_view what) noexcept;
}  // namespace bodyd::detail

#define BODYD_REQUIRE(cond, what)                                          \
  do {                                                                     \
    if (!(cond)) [[unlikely]]                                              \
      ::bodyd::detail::require_failed(__FILE__, __LINE__, #cond, (what));  \
  } while (0)
