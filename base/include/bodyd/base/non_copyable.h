// NonCopyable: a class that owns something only once (a socket, a liblo bundle, an encoder's
// buffers behind a pointer) derives from it instead of deleting its copy constructor and copy
// assignment itself. It declares no move either, so such a class is neither copied nor moved
// unless it declares its own moves.
#pragma once

#include <type_traits>

namespace bodyd {

class NonCopyable {
 public:
  NonCopyable(const NonCopyable&) = delete;
  NonCopyable& operator=(const NonCopyable&) = delete;

 protected:
  NonCopyable() = default;
  ~NonCopyable() = default;
};

namespace non_copyable_check {
struct Probe : NonCopyable {};
static_assert(!std::is_copy_constructible_v<Probe> && !std::is_copy_assignable_v<Probe>);
static_assert(!std::is_move_constructible_v<Probe> && !std::is_move_assignable_v<Probe>);
static_assert(std::is_default_constructible_v<Probe>);
}  // namespace non_copyable_check

}  // namespace bodyd
