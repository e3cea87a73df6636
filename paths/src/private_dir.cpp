#include "bodyd/paths/private_dir.h"

#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstdio>
#include <cstring>

namespace bodyd::paths {

std::string private_directory_problem(const std::filesystem::path& dir) {
  struct stat st {};
  if (::lstat(dir.c_str(), &st) != 0) return dir.string() + ": " + std::strerror(errno);
  const char* why = nullptr;
  if (S_ISLNK(st.st_mode)) why = "is a symbolic link";
  else if (!S_ISDIR(st.st_mode)) why = "is not a directory";
  else if (st.st_uid != ::geteuid()) why = "is owned by another user";
  else if ((st.st_mode & 077) != 0) why = "is open to other users";
  if (why == nullptr) return {};
  char mode[8];
  std::snprintf(mode, sizeof(mode), "%04o", static_cast<unsigned>(st.st_mode & 07777));
  return dir.string() + " " + why + " (mode " + mode + ")";
}

}  // namespace bodyd::paths
