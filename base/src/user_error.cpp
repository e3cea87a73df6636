#include "bodyd/base/user_error.h"

#include <utility>

namespace bodyd {

std::string Problem::message() const {
  std::string out = where;
  if (!what.empty()) {
    if (!out.empty()) out += ": ";
    out += what;
  }
  if (!todo.empty()) {
    if (!out.empty()) out += "; ";
    out += todo;
  }
  return out;
}

Problem Problem::under(std::string context) const {
  return Problem{std::move(context), Problem{where, what, {}}.message(), todo};
}

UserError::UserError(Problem problem) : std::runtime_error(problem.message()), problem_(std::move(problem)) {}

UserError::UserError(std::string where, std::string what, std::string todo)
    : UserError(Problem{std::move(where), std::move(what), std::move(todo)}) {}

}  // namespace bodyd
