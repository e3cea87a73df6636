#include "bodyd/client/curve_keys.h"

#include <zmq.h>

#include <cctype>
#include <cstdint>
#include <fstream>

namespace bodyd::client {

std::string read_curve_key_file(const std::filesystem::path& path, std::string& out_key) {
  std::ifstream in(path);
  if (!in) return path.string() + ": cannot open CURVE key file (create keys with bodyd --gen-keys DIR)";
  std::string line, key;
  int line_no = 0, key_line = 0;
  while (std::getline(in, line)) {
    ++line_no;
    std::string trimmed;
    for (char c : line)
      if (!std::isspace(static_cast<unsigned char>(c))) trimmed += c;
    if (trimmed.empty() || trimmed[0] == '#') continue;
    if (!key.empty()) return path.string() + ":" + std::to_string(line_no) + ": more than one key in the file";
    key = trimmed;
    key_line = line_no;
  }
  if (key.empty()) return path.string() + ": no key in the file";
  if (key.size() != 40)
    return path.string() + ":" + std::to_string(key_line) + ": a Z85 CURVE key has 40 characters, this has " +
           std::to_string(key.size());
  std::uint8_t raw[32];
  if (zmq_z85_decode(raw, key.c_str()) == nullptr)
    return path.string() + ":" + std::to_string(key_line) + ": not valid Z85 text";
  out_key = key;
  return {};
}

std::string curve_public_from_secret(const std::string& secret_key) {
  if (secret_key.size() != 40) return {};
  char pub[41] = {};
  if (zmq_curve_public(pub, secret_key.c_str()) != 0) return {};
  return pub;
}

}  // namespace bodyd::client
