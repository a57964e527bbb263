#include "common/atomic_file.h"

#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <cstring>
#include <fstream>
#include <sstream>

#include "common/errors.h"

namespace fs = std::filesystem;

namespace perf {

fs::path TempPathFor(const fs::path& target) {
  static std::atomic<unsigned> counter{0};
  const std::string suffix =
      StrCat(".tmp", ::getpid(), "-", counter.fetch_add(1), target.extension().string());
  return target.parent_path() / (target.stem().string() + suffix);
}

void WriteAtomically(const fs::path& target, const std::function<void(const fs::path&)>& write) {
  const fs::path tmp = TempPathFor(target);
  try {
    write(tmp);
    std::error_code ec;
    fs::rename(tmp, target, ec);
    if (ec) {
      throw IoError(target.string(), "cannot move the finished file into place: " + ec.message(),
                    "check that the folder is writable and on one file system");
    }
  } catch (...) {
    std::error_code ignored;
    fs::remove(tmp, ignored);
    throw;
  }
}

void WriteFileAtomically(const fs::path& target, std::string_view contents) {
  WriteAtomically(target, [&](const fs::path& tmp) {
    std::ofstream out(tmp, std::ios::binary | std::ios::trunc);
    if (!out) {
      throw IoError(tmp.string(), StrCat("cannot create file: ", std::strerror(errno)),
                    "check that the folder exists and is writable");
    }
    out.write(contents.data(), static_cast<std::streamsize>(contents.size()));
    out.flush();
    if (!out) throw IoError(tmp.string(), "write failed (disk full?)");
  });
}

void EnsureWritableDirectory(const fs::path& dir) {
  std::error_code ec;
  fs::create_directories(dir, ec);
  if (ec || !fs::is_directory(dir)) {
    throw IoError(dir.string(), "cannot create the folder: " + (ec ? ec.message() : "not a folder"),
                  "choose a writable location");
  }
  if (::access(dir.c_str(), W_OK | X_OK) != 0) {
    throw IoError(dir.string(), "the folder is not writable", "choose a writable location or fix its permissions");
  }
}

std::string ReadFileToString(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw IoError(path.string(), StrCat("cannot open for reading: ", std::strerror(errno)));
  std::ostringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

}  // namespace perf
