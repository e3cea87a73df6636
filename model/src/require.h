// Internal: a broken precondition is a bug in the caller, so stop loudly in every build type
// (STYLE.md, "three kinds of failure").
#pragma once

#include <cstdio>
#include <cstdlib>

#define BODYD_REQUIRE(cond, what)                                                     \
  do {                                                                                \
    if (!(cond)) {                                                                    \
      std::fprintf(stderr, "%s:%d: bug: %s (%s)\n", __FILE__, __LINE__, what, #cond); \
      std::abort();                                                                   \
    }                                                                                 \
  } while (0)
