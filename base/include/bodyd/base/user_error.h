// The failure a user can fix (docs/architecture.md, "Errors"): a bad file, spec, option or flag, a
// busy port, a missing device. Its message says where, what is wrong and what the user can do, in
// that order, so every tool and the daemon print the same kind of line:
//
//   throw BvhError(fmt::format("{}:{}", file, line), "expected '{' after the joint name",
//                  "re-export the clip as BVH");
//   // what(): "walk.bvh:12: expected '{' after the joint name; re-export the clip as BVH"
//
// A bug (a broken invariant of bodyd's own code) is BODYD_REQUIRE (require.h), never a UserError;
// an expected non-event is a value. Each module's typed error (BvhError, ModelFileError, ...)
// derives from UserError, so a program's start catches them all as one.
#pragma once

#include <stdexcept>
#include <string>

namespace bodyd {

struct Problem {
  // Where: file:line, a byte offset, a field, flag, spec, endpoint or device path; "" when the
  // caller's context already says it.
  std::string where;
  // What is wrong (never empty).
  std::string what;
  // What the user can do; "" only when nothing useful can be said.
  std::string todo;

  // "WHERE: WHAT; TODO", leaving out an empty part and its separator.
  [[nodiscard]] std::string message() const;
  // The same problem seen from an outer `context` (a method, a step, a clip) that caught it: the
  // context becomes where, the old where joins what, the todo stays. Its message is
  // "CONTEXT: WHERE: WHAT; TODO".
  [[nodiscard]] Problem under(std::string context) const;
};

class UserError : public std::runtime_error {
 public:
  explicit UserError(Problem problem);
  UserError(std::string where, std::string what, std::string todo = {});

  [[nodiscard]] const Problem& problem() const noexcept { return problem_; }

 private:
  Problem problem_;
};

}  // namespace bodyd
