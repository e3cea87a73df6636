#include "bodyd/base/require.h"

#include <cstdio>
#include <cstdlib>

namespace bodyd::detail {

void require_failed(const char* file, int line, const char* condition, std::string_view what) noexcept {
  std::fprintf(stderr, "%s:%d: bug: %.*s (%s)\n", file, line, static_cast<int>(what.size()), what.data(), condition);
  std::fflush(stderr);
  std::abort();
}

}  // namespace bodyd::detail
