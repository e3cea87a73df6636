#include "persisted_file.h"

#include "bodyd/base/non_copyable.h"

#include <fmt/format.h>

#include <cerrno>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

namespace bodyd::daemon {

namespace {

// Closes a descriptor at the end of its scope.
struct ScopedFd : NonCopyable {
  explicit ScopedFd(int descriptor) : fd(descriptor) {}
  ~ScopedFd() {
    if (fd >= 0) ::close(fd);
  }
  const int fd;
};

std::string errno_text() { return std::strerror(errno); }

}  // namespace

std::optional<std::string> read_persisted_file(const std::filesystem::path& path, std::size_t max_bytes,
                                               std::string& error) {
  error.clear();
  // O_NONBLOCK: a FIFO at the path must not stop the start; fstat then refuses it.
  const ScopedFd file{::open(path.c_str(), O_RDONLY | O_NONBLOCK | O_CLOEXEC)};
  if (file.fd < 0) {
    if (errno == ENOENT) return std::nullopt;
    error = fmt::format("{}: cannot be opened: {}", path.string(), errno_text());
    return std::nullopt;
  }
  struct stat st {};
  if (::fstat(file.fd, &st) != 0 || !S_ISREG(st.st_mode)) {
    error = fmt::format("{}: not a regular file", path.string());
    return std::nullopt;
  }
  const auto too_large = [&] {
    error = fmt::format("{}: larger than {} bytes, the most a file bodyd keeps may hold", path.string(), max_bytes);
    return std::nullopt;
  };
  if (static_cast<std::uintmax_t>(st.st_size) > max_bytes) return too_large();
  // One byte more than the limit, in case the file grew since fstat.
  std::string text(max_bytes + 1, '\0');
  std::size_t used = 0;
  while (used < text.size()) {
    const ssize_t n = ::read(file.fd, text.data() + used, text.size() - used);
    if (n < 0 && errno == EINTR) continue;
    if (n < 0) {
      error = fmt::format("{}: cannot be read: {}", path.string(), errno_text());
      return std::nullopt;
    }
    if (n == 0) break;
    used += static_cast<std::size_t>(n);
  }
  if (used > max_bytes) return too_large();
  text.resize(used);
  return text;
}

std::string create_private_directories(const std::filesystem::path& dir) {
  std::filesystem::path made;
  for (const std::filesystem::path& part : dir) {
    made /= part;
    if (part.empty() || part == made.root_path()) continue;
    if (::mkdir(made.c_str(), 0700) == 0 || errno == EEXIST) continue;
    const std::string e = errno_text();
    struct stat st {};
    if (::stat(made.c_str(), &st) == 0 && S_ISDIR(st.st_mode)) continue;  // e.g. EROFS for a folder that exists
    return fmt::format("{}: cannot create the folder: {}", made.string(), e);
  }
  return {};
}

std::string replace_persisted_file(const std::filesystem::path& path, std::string_view text, mode_t mode) {
  std::error_code ec;
  if (path.has_parent_path()) std::filesystem::create_directories(path.parent_path(), ec);
  std::string tmp = path.string() + ".XXXXXX";
  const ScopedFd file{::mkostemp(tmp.data(), O_CLOEXEC)};
  if (file.fd < 0)
    return fmt::format("{}: cannot create a temporary file beside it: {} (is its folder writable?)", path.string(),
                       errno_text());
  const auto fail = [&](const char* what) {
    std::string e = fmt::format("{}: {}: {}", tmp, what, errno_text());
    ::unlink(tmp.c_str());
    return e;
  };
  for (std::size_t done = 0; done < text.size();) {
    const ssize_t n = ::write(file.fd, text.data() + done, text.size() - done);
    if (n < 0 && errno == EINTR) continue;
    if (n < 0) return fail("cannot write");
    done += static_cast<std::size_t>(n);
  }
  if (::fchmod(file.fd, mode) != 0) return fail("cannot set its permissions");
  if (::fsync(file.fd) != 0) return fail("cannot flush it to the disk");
  if (::rename(tmp.c_str(), path.c_str()) != 0) {
    const std::string e = fmt::format("{}: cannot replace it: {}", path.string(), errno_text());
    ::unlink(tmp.c_str());
    return e;
  }
  return {};
}

}  // namespace bodyd::daemon
