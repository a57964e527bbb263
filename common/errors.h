// Error types shared by every stage.
//
// Two tiers (as in COLMAP's logging.h): PERF_CHECK for invariants of our own code, which
// throws InternalError with file:line; and typed exceptions for what the user gave us
// (InputError: a bad value in a named file and field, with what to do about it; IoError: a
// path that cannot be read or written). The CLI maps each type to a message and exit code.
#pragma once

#include <sstream>
#include <stdexcept>
#include <string>

namespace perf {

class Error : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// Bad input data: names the file, the field, the offending value, and what to do.
class InputError : public Error {
 public:
  InputError(std::string file, std::string field, std::string value, std::string problem,
             std::string hint = {});

  const std::string& file() const { return file_; }
  const std::string& field() const { return field_; }
  const std::string& value() const { return value_; }

 private:
  std::string file_, field_, value_;
};

// A path that cannot be opened, read, created or written.
class IoError : public Error {
 public:
  IoError(std::string path, std::string problem, std::string hint = {});
  const std::string& path() const { return path_; }

 private:
  std::string path_;
};

// Not enough memory (or another machine resource) for what was asked: names what was needed,
// what is available, and what to change.
class ResourceError : public Error {
 public:
  using Error::Error;
};

// The user stopped the work (Ctrl-C) at a safe point; what was saved can be resumed.
class Interrupted : public Error {
 public:
  using Error::Error;
};

// A broken invariant in PERF itself (a bug), with the source location.
class InternalError : public Error {
 public:
  using Error::Error;
};

namespace detail {
[[noreturn]] void ThrowCheckFailed(const char* file, int line, const char* expr,
                                   const std::string& message);
}  // namespace detail

// Formats any streamable values into a string: StrCat("n = ", n).
template <typename... Args>
std::string StrCat(const Args&... args) {
  std::ostringstream out;
  (out << ... << args);
  return out.str();
}

}  // namespace perf

#define PERF_CHECK(cond)                                                      \
  do {                                                                        \
    if (!(cond)) ::perf::detail::ThrowCheckFailed(__FILE__, __LINE__, #cond, {}); \
  } while (0)

#define PERF_CHECK_MSG(cond, ...)                                              \
  do {                                                                         \
    if (!(cond))                                                               \
      ::perf::detail::ThrowCheckFailed(__FILE__, __LINE__, #cond,              \
                                       ::perf::StrCat(__VA_ARGS__));           \
  } while (0)
