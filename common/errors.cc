#include "common/errors.h"

namespace perf {
namespace {

std::string FormatInput(const std::string& file, const std::string& field,
                        const std::string& value, const std::string& problem,
                        const std::string& hint) {
  std::string msg = file;
  if (!field.empty()) msg += ": " + field;
  if (!value.empty()) msg += " = " + value;
  msg += ": " + problem;
  if (!hint.empty()) msg += ". " + hint;
  return msg;
}

}  // namespace

InputError::InputError(std::string file, std::string field, std::string value,
                       std::string problem, std::string hint)
    : Error(FormatInput(file, field, value, problem, hint)),
      file_(std::move(file)),
      field_(std::move(field)),
      value_(std::move(value)) {}

IoError::IoError(std::string path, std::string problem, std::string hint)
    : Error(path + ": " + problem + (hint.empty() ? "" : ". " + hint)), path_(std::move(path)) {}

namespace detail {
void ThrowCheckFailed(const char* file, int line, const char* expr, const std::string& message) {
  std::string msg = StrCat("internal error at ", file, ":", line, ": check failed: ", expr);
  if (!message.empty()) msg += " (" + message + ")";
  throw InternalError(msg);
}
}  // namespace detail

}  // namespace perf
