#include "bodyd/test/files.h"

#include <fstream>
#include <iterator>
#include <sstream>

namespace bodyd::test {

std::string read_file(const std::filesystem::path& path) {
  std::ifstream in(path, std::ios::binary);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

std::vector<std::uint8_t> read_file_bytes(const std::filesystem::path& path) {
  std::ifstream in(path, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

bool write_file(const std::filesystem::path& path, std::string_view content) {
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  out.write(content.data(), static_cast<std::streamsize>(content.size()));
  return static_cast<bool>(out);
}

std::size_t samples_on_disk(const std::filesystem::path& path) {
  std::size_t n = 0;
  std::istringstream in(read_file(path));
  for (std::string line; std::getline(in, line);) n += !line.empty() && line[0] != '#' && !line.starts_with("t_ns");
  return n;
}

}  // namespace bodyd::test
