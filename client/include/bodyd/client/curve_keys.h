// ZeroMQ CURVE key files (docs/daemon.md, "Security"): the files `bodyd --gen-keys` writes, read by
// bodyd (its own pair, the --curve-allow list) and by its clients (bodyd-ctl's --curve-server-key
// and --curve-client-key). Keys are Z85 text, 40 characters.
#pragma once

#include <filesystem>
#include <string>

namespace bodyd::client {

// Reads a Z85 key file (40 key characters; whitespace and '#' comment lines ignored).
// Empty on success, else "file: what is wrong".
[[nodiscard]] std::string read_curve_key_file(const std::filesystem::path& path, std::string& out_key);

// The public key of a Z85 secret key; empty when the secret key is malformed.
[[nodiscard]] std::string curve_public_from_secret(const std::string& secret_key);

}  // namespace bodyd::client
