// Model-file container decoder and model loader (docs/model-file.md).
#include "bodyd/inference/model_file.h"

#include "bodyd/base/little_endian.h"
#include "bodyd/base/require.h"
#include "bodyd/inference/denoiser.h"
#include "bodyd/inference/features.h"

#include <fmt/format.h>
#include <fmt/ranges.h>
#include <nlohmann/json.hpp>
#include <openssl/evp.h>

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstring>
#include <fstream>
#include <limits>
#include <set>

namespace bodyd::inference {
namespace {

static_assert(std::endian::native == std::endian::little, "model files are little-endian; add byte swapping");

// Headers of real models are a few kB; anything above this is a corrupt length field
// (safetensors uses the same limit).
constexpr std::uint64_t kMaxHeaderBytes = 100u * 1024u * 1024u;
constexpr std::string_view kSha256Prefix = "sha256:";
constexpr std::size_t kSha256HexChars = 64;
// No model comes near this (the default is about 11 MB); a larger file is not read at all.
constexpr std::uint64_t kMaxModelFileBytes = std::uint64_t{2} << 30;

using Json = nlohmann::json;

// where: "model file 'SOURCE'".
[[noreturn]] void fail(const std::string& source, const std::string& what, std::string todo = {}) {
  throw ModelFileError(fmt::format("model file '{}'", source), what, std::move(todo));
}

// SHA-256 of the concatenated parts, as 64 lower-case hex digits.
std::string sha256_hex(std::initializer_list<std::span<const std::byte>> parts) {
  EVP_MD_CTX* ctx = EVP_MD_CTX_new();
  unsigned char digest[EVP_MAX_MD_SIZE];
  unsigned int length = 0;
  bool ok = ctx != nullptr && EVP_DigestInit_ex(ctx, EVP_sha256(), nullptr) == 1;
  for (const auto& part : parts) ok = ok && EVP_DigestUpdate(ctx, part.data(), part.size()) == 1;
  ok = ok && EVP_DigestFinal_ex(ctx, digest, &length) == 1;
  EVP_MD_CTX_free(ctx);
  BODYD_REQUIRE(ok && length == 32, "SHA-256 from OpenSSL failed");
  std::string hex;
  for (unsigned int i = 0; i < length; ++i) hex += fmt::format("{:02x}", digest[i]);
  return hex;
}

// "sha256:" + 64 lower-case hex digits -> the hex digits, or empty.
std::string_view sha256_digits(std::string_view text) {
  if (text.size() != kSha256Prefix.size() + kSha256HexChars || text.substr(0, kSha256Prefix.size()) != kSha256Prefix)
    return {};
  const std::string_view hex = text.substr(kSha256Prefix.size());
  for (char c : hex)
    if (!((c >= '0' && c <= '9') || (c >= 'a' && c <= 'f'))) return {};
  return hex;
}

std::string shape_str(const std::vector<std::int64_t>& shape) { return fmt::format("[{}]", fmt::join(shape, ",")); }

std::uint64_t read_u64_le(const std::byte* p) { return load_le<std::uint64_t>(reinterpret_cast<const std::uint8_t*>(p)); }

// A non-negative integer JSON value that fits `limit`, or nullopt.
std::optional<std::uint64_t> json_uint(const Json& j, std::uint64_t limit) {
  if (j.is_number_unsigned()) {
    auto v = j.get<std::uint64_t>();
    if (v <= limit) return v;
  } else if (j.is_number_integer()) {
    auto v = j.get<std::int64_t>();
    if (v >= 0 && static_cast<std::uint64_t>(v) <= limit) return static_cast<std::uint64_t>(v);
  }
  return std::nullopt;
}

const std::string& require_meta(const std::string& source, const TensorFile& file, std::string_view key) {
  auto it = file.metadata.find(key);
  if (it == file.metadata.end()) fail(source, fmt::format("metadata key \"{}\" is missing", key));
  return it->second;
}

Json parse_meta_json(const std::string& source, std::string_view key, const std::string& text) {
  try {
    return Json::parse(text);
  } catch (const Json::exception& e) {  // parse_error, or out_of_range for a number like 1e999
    fail(source, fmt::format("metadata \"{}\" is not valid JSON ({})", key, e.what()));
  }
}

// Metadata "config": the fields `arch` names, each an integer in [1, its max] and a multiple of its
// multiple_of, in the row's order; then the generic W, D, T, and D == features::kDim.
ModelConfig parse_config(const std::string& source, const std::string& text, const Architecture& arch) {
  const Json j = parse_meta_json(source, "config", text);
  if (!j.is_object()) {
    std::string keys;
    for (const ConfigField& f : arch.config) keys += (keys.empty() ? "" : ",") + std::string(f.key);
    fail(source, fmt::format("metadata \"config\" must be a JSON object {{{}}}", keys));
  }
  ModelConfig c;
  for (const ConfigField& field : arch.config) {
    const std::string key(field.key);
    auto it = j.find(key);
    if (it == j.end()) fail(source, fmt::format("config key \"{}\" is missing (config: {})", key, text));
    const int max = std::min(field.max, kMaxConfigValue);
    auto v = json_uint(*it, static_cast<std::uint64_t>(max));
    if (!v || *v < 1) fail(source, fmt::format("config \"{}\" must be an integer in [1, {}], got {}", key, max, it->dump()));
    const int value = static_cast<int>(*v);
    if (field.multiple_of > 1 && value % field.multiple_of != 0) {
      fail(source, field.multiple_of == 2
                       ? fmt::format("config \"{}\" must be even, got {}", key, value)
                       : fmt::format("config \"{}\" must be a multiple of {}, got {}", key, field.multiple_of, value));
    }
    c.set(key, value);
  }
  for (std::string_view key : {kConfigFrames, kConfigFeatures, kConfigSteps}) {
    // A row without them is a bug of this build, not of the file.
    BODYD_REQUIRE(c.find(key).has_value(), fmt::format("architecture {}: its config lacks \"{}\"", arch.name, key));
  }
  if (c.dim() != features::kDim) {
    fail(source,
         fmt::format("config \"D\" is {} but this build's features have kDim = {} (feature_version {})", c.dim(),
                     features::kDim, features::kVersion),
         "use a model trained for this version");
  }
  return c;
}

Skeleton parse_skeleton(const std::string& source, const std::string& text) {
  const Json j = parse_meta_json(source, "skeleton", text);
  auto bad = [&](const std::string& what) -> void { fail(source, "metadata \"skeleton\": " + what); };
  if (!j.is_object()) bad("must be a JSON object {names, parents, offsets_m}");
  for (const char* key : {"names", "parents", "offsets_m"}) {
    if (!j.contains(key) || !j[key].is_array()) bad(fmt::format("\"{}\" must be an array", key));
    if (j[key].size() != static_cast<std::size_t>(kModelSkeletonJoints)) {
      bad(fmt::format("\"{}\" has {} entries, expected {} joints", key, j[key].size(), kModelSkeletonJoints));
    }
  }
  Skeleton s;
  std::set<std::string, std::less<>> seen;
  for (int i = 0; i < kModelSkeletonJoints; ++i) {
    const Json& name = j["names"][i];
    if (!name.is_string() || name.get<std::string>().empty()) bad(fmt::format("names[{}] must be a non-empty string", i));
    if (!seen.insert(name.get<std::string>()).second) bad(fmt::format("joint name \"{}\" appears twice", name.get<std::string>()));
    s.names.push_back(name.get<std::string>());

    const Json& parent = j["parents"][i];
    if (!parent.is_number_integer()) bad(fmt::format("parents[{}] must be an integer", i));
    const auto p = parent.get<std::int64_t>();
    if (i == 0 ? p != -1 : (p < 0 || p >= i)) {
      bad(fmt::format("parents[{}] = {}: the root (joint 0) has parent -1 and every other joint a parent before it", i, p));
    }
    s.parents.push_back(static_cast<int>(p));

    const Json& off = j["offsets_m"][i];
    if (!off.is_array() || off.size() != 3) bad(fmt::format("offsets_m[{}] must be [x, y, z]", i));
    Vec3 v;
    for (int k = 0; k < 3; ++k) {
      if (!off[k].is_number() || !std::isfinite(off[k].get<double>())) bad(fmt::format("offsets_m[{}][{}] must be a finite number", i, k));
      v[k] = off[k].get<double>();
    }
    s.offsets.push_back(v);
  }
  s.end_sites.assign(kModelSkeletonJoints, std::nullopt);
  if (std::string err = features::check_skeleton(s); !err.empty()) bad(err);
  return s;
}

int parse_int_meta(const std::string& source, std::string_view key, const std::string& text) {
  try {
    std::size_t used = 0;
    const int v = std::stoi(text, &used);
    if (used == text.size()) return v;
  } catch (const std::exception&) {
  }
  fail(source, fmt::format("metadata \"{}\" must be an integer, got \"{}\"", key, text));
}

double parse_double_meta(const std::string& source, std::string_view key, const std::string& text) {
  try {
    std::size_t used = 0;
    const double v = std::stod(text, &used);
    if (used == text.size() && std::isfinite(v)) return v;
  } catch (const std::exception&) {
  }
  fail(source, fmt::format("metadata \"{}\" must be a finite number, got \"{}\"", key, text));
}

// Checks metadata "checksum" (docs/model-file.md, "Checksum"); throws ModelFileError naming what differs.
void verify_checksum(std::span<const std::byte> length_and_header, std::span<const std::byte> data, const TensorFile& file,
                     const std::string& checksum, const std::string& source);

}  // namespace

TensorFile parse_tensor_file(std::span<const std::byte> bytes, const std::string& source) {
  if (bytes.size() < 8) {
    fail(source, fmt::format("truncated: {} bytes, shorter than the 8-byte header length", bytes.size()));
  }
  const std::uint64_t n = read_u64_le(bytes.data());
  if (n < 2 || n > kMaxHeaderBytes) {
    // The value is not printed: it is the file's first 8 bytes, whatever the file is.
    fail(source, fmt::format("its first 8 bytes are not a header length in 2..{}; not a bodyd model file, or corrupt",
                             kMaxHeaderBytes));
  }
  if (n > bytes.size() - 8) {
    fail(source, fmt::format("truncated: header length {} but only {} bytes follow the length field", n, bytes.size() - 8));
  }
  const auto* header_begin = reinterpret_cast<const char*>(bytes.data() + 8);
  Json header;
  try {
    header = Json::parse(header_begin, header_begin + n);
  } catch (const Json::parse_error& e) {
    // Only the position: the parser's message quotes the text it read.
    fail(source, fmt::format("header JSON is malformed at byte {} of the header; not a bodyd model file, or corrupt",
                             e.byte));
  } catch (const Json::exception&) {  // out_of_range: a number that overflows a double (found by make fuzz)
    fail(source, "header JSON holds a number that overflows a double; not a bodyd model file, or corrupt");
  }
  if (!header.is_object()) fail(source, "header JSON must be an object");

  const std::span<const std::byte> data = bytes.subspan(8 + n);
  TensorFile out;
  std::vector<std::tuple<std::uint64_t, std::uint64_t, std::string>> ranges;
  for (const auto& [name, entry] : header.items()) {
    if (name == "__metadata__") {
      if (!entry.is_object()) fail(source, "\"__metadata__\" must be an object of strings");
      for (const auto& [key, value] : entry.items()) {
        if (!value.is_string()) fail(source, fmt::format("metadata \"{}\" must be a string, got {}", key, value.dump()));
        out.metadata.emplace(key, value.get<std::string>());
      }
      continue;
    }
    // The binding is copied: clang 14 cannot capture structured bindings (make fuzz builds with it).
    auto where = [&, tensor = std::string(name)](const std::string& what) {
      fail(source, fmt::format("tensor \"{}\": {}", tensor, what));
    };
    if (!entry.is_object()) where("entry must be an object {dtype, shape, data_offsets}");
    if (!entry.contains("dtype") || !entry["dtype"].is_string()) where("\"dtype\" is missing");
    if (entry["dtype"] != "F32") where(fmt::format("dtype {} is not supported (bodyd model files store F32)", entry["dtype"].dump()));
    if (!entry.contains("shape") || !entry["shape"].is_array()) where("\"shape\" must be an array");
    TensorF32 t;
    std::uint64_t count = 1;
    for (const Json& d : entry["shape"]) {
      auto v = json_uint(d, std::numeric_limits<std::uint32_t>::max());
      if (!v) where(fmt::format("shape {} has an invalid dimension", entry["shape"].dump()));
      t.shape.push_back(static_cast<std::int64_t>(*v));
      // Any real tensor is far below 2^40 elements; checked per step so the product cannot overflow.
      count *= *v;
      if (count > (std::uint64_t{1} << 40)) where(fmt::format("shape {} is absurdly large", entry["shape"].dump()));
    }
    if (!entry.contains("data_offsets") || !entry["data_offsets"].is_array() || entry["data_offsets"].size() != 2) {
      where("\"data_offsets\" must be [begin, end]");
    }
    const auto begin = json_uint(entry["data_offsets"][0], std::numeric_limits<std::uint64_t>::max());
    const auto end = json_uint(entry["data_offsets"][1], std::numeric_limits<std::uint64_t>::max());
    if (!begin || !end || *begin > *end) where(fmt::format("data_offsets {} invalid", entry["data_offsets"].dump()));
    if (*end > data.size()) {
      where(fmt::format("data_offsets [{}, {}] run past the end of the data ({} bytes); the file is truncated", *begin, *end, data.size()));
    }
    if (*end - *begin != count * sizeof(float)) {
      where(fmt::format("data_offsets [{}, {}] hold {} bytes but shape {} needs {}", *begin, *end, *end - *begin,
                        shape_str(t.shape), count * sizeof(float)));
    }
    t.data.resize(count);
    if (count > 0) std::memcpy(t.data.data(), data.data() + *begin, count * sizeof(float));
    ranges.emplace_back(*begin, *end, name);
    out.tensors.emplace(name, std::move(t));
  }
  // Sorted by begin, a range overlaps an earlier one iff it starts before the furthest end so far.
  std::sort(ranges.begin(), ranges.end());
  const std::tuple<std::uint64_t, std::uint64_t, std::string>* furthest = nullptr;
  for (const auto& r : ranges) {
    const auto& [b, e, name] = r;
    if (b == e) continue;  // empty tensors occupy no bytes
    if (furthest != nullptr && b < std::get<1>(*furthest)) {
      fail(source, fmt::format("tensors \"{}\" [{}, {}] and \"{}\" [{}, {}] overlap", std::get<2>(*furthest),
                               std::get<0>(*furthest), std::get<1>(*furthest), name, b, e));
    }
    if (furthest == nullptr || e > std::get<1>(*furthest)) furthest = &r;
  }
  const std::uint64_t data_end = furthest != nullptr ? std::get<1>(*furthest) : 0;
  if (data_end != data.size()) {
    fail(source, fmt::format("{} bytes after the end of the last tensor (byte {} of the data); the file has trailing "
                             "bytes or gaps the header does not describe",
                             data.size() - data_end, data_end));
  }
  if (auto it = out.metadata.find(kChecksumKey); it != out.metadata.end())
    verify_checksum(bytes.first(8 + n), data, out, it->second, source);
  return out;
}

namespace {
void verify_checksum(std::span<const std::byte> length_and_header, std::span<const std::byte> data, const TensorFile& file,
                     const std::string& checksum, const std::string& source) {
  const std::string_view expected = sha256_digits(checksum);
  if (expected.empty()) {
    fail(source, fmt::format("metadata \"{}\" must be \"sha256:\" and 64 lower-case hex digits", kChecksumKey));
  }
  // The digest covers the length field, the header with the checksum's digits as '0's (it was
  // computed before they were written), and the data.
  std::string header(reinterpret_cast<const char*>(length_and_header.data()), length_and_header.size());
  const std::string quoted = fmt::format("\"{}\"", checksum);
  const auto at = header.find(quoted);
  if (at == std::string::npos || header.find(quoted, at + 1) != std::string::npos) {
    fail(source, fmt::format("metadata \"{}\" is not written as one plain JSON string in the header", kChecksumKey));
  }
  std::fill_n(header.begin() + static_cast<std::ptrdiff_t>(at + 1 + kSha256Prefix.size()), kSha256HexChars, '0');
  const std::string actual =
      sha256_hex({std::as_bytes(std::span<const char>(header.data(), header.size())), data});
  if (actual == expected) return;
  // Name what differs: a tensor whose bytes no longer match their own digest, else the header.
  std::string what = "the header (metadata such as fps or config, or the tensor table)";
  if (auto it = file.metadata.find(kTensorChecksumsKey); it != file.metadata.end()) {
    Json sums;
    try {
      sums = Json::parse(it->second);
    } catch (const Json::exception&) {
    }
    if (sums.is_object()) {
      for (const auto& [name, t] : file.tensors) {
        const auto entry = sums.find(name);
        if (entry == sums.end() || !entry->is_string()) continue;
        const std::string stored = entry->get<std::string>();
        const std::string_view want = sha256_digits(stored);
        const auto bytes = std::as_bytes(std::span<const float>(t.data));
        if (!want.empty() && sha256_hex({bytes}) != want) {
          what = fmt::format("the data of tensor \"{}\"", name);
          break;
        }
      }
    }
  }
  fail(source,
       fmt::format("checksum mismatch: {} changed after the file was written (stored sha256:{}..., contents hash to "
                   "sha256:{}...); the file is corrupt",
                   what, expected.substr(0, 12), actual.substr(0, 12)),
       "copy or export it again");
}
}  // namespace

namespace {
// Reads a container, checking its size against its header before reading the tensor data: a
// file that is not a model costs 8 bytes of reading, and one whose size differs from what its
// header describes (truncated, or with trailing bytes) is refused before its data is read.
std::vector<std::byte> read_file_bytes(const std::filesystem::path& path) {
  const std::string source = path.string();
  std::error_code ec;
  const auto status = std::filesystem::status(path, ec);
  if (!std::filesystem::exists(status)) fail(source, "does not exist");
  if (std::filesystem::is_directory(status)) fail(source, "is a directory, not a model file");
  if (!std::filesystem::is_regular_file(status)) fail(source, "is not a regular file");
  std::ifstream in(path, std::ios::binary);
  if (!in) fail(source, "cannot be opened for reading (permissions?)");
  const std::uintmax_t size = std::filesystem::file_size(path, ec);
  if (ec) fail(source, "cannot determine its size");
  if (size > kMaxModelFileBytes) {
    fail(source, fmt::format("{} bytes, more than the {} a model file may have; not a bodyd model file", size,
                             kMaxModelFileBytes));
  }
  std::vector<std::byte> bytes(std::min<std::uintmax_t>(size, 8));
  auto read = [&](std::size_t from, std::size_t count) {
    if (count > 0 && !in.read(reinterpret_cast<char*>(bytes.data() + from), static_cast<std::streamsize>(count)))
      fail(source, "read error (the file changed while it was read?)");
  };
  read(0, bytes.size());
  if (size < 8) return bytes;  // parse_tensor_file names the problem
  const std::uint64_t n = read_u64_le(bytes.data());
  if (n < 2 || n > kMaxHeaderBytes || n > size - 8) return bytes;  // likewise, from these 8 bytes only
  bytes.resize(8 + n);
  read(8, n);
  // The data size the header describes: the largest end offset. A header the decoder would
  // refuse anyway is left to it (it reads no further).
  const Json header = Json::parse(reinterpret_cast<const char*>(bytes.data() + 8),
                                  reinterpret_cast<const char*>(bytes.data() + 8 + n), nullptr, false);
  if (!header.is_object()) return bytes;
  std::uint64_t data_end = 0;
  for (const auto& [name, entry] : header.items()) {
    if (name == "__metadata__" || !entry.is_object() || !entry.contains("data_offsets")) continue;
    const Json& o = entry["data_offsets"];
    if (!o.is_array() || o.size() != 2) return bytes;
    const auto e = json_uint(o[1], kMaxModelFileBytes);
    if (!e) return bytes;
    data_end = std::max(data_end, *e);
  }
  const std::uint64_t expected = 8 + n + data_end;
  if (size > expected) {
    fail(source, fmt::format("{} bytes after the end of the last tensor (the header describes {} bytes, the file has "
                             "{}); the file has trailing bytes",
                             size - expected, expected, size));
  }
  // A shorter file is read whole (it is no larger than its header says): the decoder names the
  // tensor that runs past its end.
  bytes.resize(size);
  read(8 + n, size - 8 - n);
  return bytes;
}
}  // namespace

TensorFile read_tensor_file(const std::filesystem::path& path) {
  const auto bytes = read_file_bytes(path);
  return parse_tensor_file(bytes, path.string());
}

ModelConfig::ModelConfig(std::initializer_list<std::pair<std::string, int>> values) {
  for (const auto& [key, value] : values) set(key, value);
}

std::optional<int> ModelConfig::find(std::string_view key) const {
  for (const auto& [k, v] : values_)
    if (k == key) return v;
  return std::nullopt;
}

int ModelConfig::at(std::string_view key) const {
  if (auto v = find(key)) return *v;
  throw ModelFileError("model config", fmt::format("key \"{}\" is missing (config: {})", key, to_string()));
}

void ModelConfig::set(std::string_view key, int value) {
  for (auto& [k, v] : values_) {
    if (k == key) {
      v = value;
      return;
    }
  }
  values_.emplace_back(std::string(key), value);
}

std::string ModelConfig::to_string() const {
  std::string out;
  for (const auto& [k, v] : values_) out += fmt::format("{}{}={}", out.empty() ? "" : " ", k, v);
  return out;
}

const TensorF32& Model::tensor(std::string_view name) const {
  auto it = tensors.find(name);
  if (it == tensors.end())
    throw ModelFileError(fmt::format("model file '{}'", source), fmt::format("tensor \"{}\" is missing", name));
  return it->second;
}

Model parse_model(std::span<const std::byte> bytes, const std::string& source) {
  TensorFile file = parse_tensor_file(bytes, source);
  Model m;
  m.source = source;

  const std::string& format = require_meta(source, file, "format");
  if (format != kModelFormat) {
    fail(source, fmt::format("metadata \"format\" is \"{}\", expected \"{}\"; not a bodyd model", format, kModelFormat));
  }
  // parse_tensor_file verified the checksum if there is one; a model file must have one.
  if (!file.metadata.contains(kChecksumKey)) {
    fail(source, fmt::format("metadata \"{}\" is missing (written before checksums were added)", kChecksumKey),
         "stamp it with python3 training/model_net.py --restamp FILE");
  }
  const std::string& version = require_meta(source, file, "format_version");
  if (version != kModelFormatVersion) {
    fail(source,
         fmt::format("format_version \"{}\" is not supported (this build reads \"{}\")", version, kModelFormatVersion),
         "use a matching bodyd or re-export the model");
  }
  const std::string& arch = require_meta(source, file, "architecture");
  const Architecture* architecture = find_architecture(arch);
  if (architecture == nullptr) {
    fail(source, fmt::format("architecture \"{}\" is unknown (this build runs: {})", arch, architecture_names()),
         "use a bodyd that knows it or a model of a known architecture");
  }
  m.feature_version = parse_int_meta(source, "feature_version", require_meta(source, file, "feature_version"));
  if (m.feature_version != features::kVersion) {
    fail(source,
         fmt::format("feature_version {} does not match this build's features::kVersion {}", m.feature_version,
                     features::kVersion),
         "retrain or export the model with the current features");
  }
  m.config = parse_config(source, require_meta(source, file, "config"), *architecture);
  m.skeleton = parse_skeleton(source, require_meta(source, file, "skeleton"));
  m.fps = parse_double_meta(source, "fps", require_meta(source, file, "fps"));
  if (m.fps <= 0.0) fail(source, fmt::format("metadata \"fps\" must be > 0, got {}", m.fps));
  m.provenance_json = require_meta(source, file, "provenance");
  if (!parse_meta_json(source, "provenance", m.provenance_json).is_object()) {
    fail(source, "metadata \"provenance\" must be a JSON object");
  }

  // Tensors: exactly the expected set, with exactly the expected shapes, all finite.
  const TensorShapes expected = expected_tensors(*architecture, m.config);
  std::set<std::string, std::less<>> expected_names;
  for (const auto& [name, shape] : expected) {
    expected_names.insert(name);
    auto it = file.tensors.find(name);
    if (it == file.tensors.end()) fail(source, fmt::format("tensor \"{}\" (shape {}) is missing", name, shape_str(shape)));
    if (it->second.shape != shape) {
      fail(source, fmt::format("tensor \"{}\" has shape {}, expected {} for config {}", name, shape_str(it->second.shape),
                               shape_str(shape), m.config.to_string()));
    }
    const auto& d = it->second.data;
    if (auto bad = std::find_if(d.begin(), d.end(), [](float x) { return !std::isfinite(x); }); bad != d.end()) {
      fail(source, fmt::format("tensor \"{}\" has a non-finite value ({}) at flat index {}", name, *bad, bad - d.begin()));
    }
  }
  for (const auto& [name, t] : file.tensors) {
    if (!expected_names.contains(name)) {
      fail(source, fmt::format("unexpected tensor \"{}\" (shape {}) for architecture {} with config {}", name,
                               shape_str(t.shape), arch, m.config.to_string()));
    }
  }

  m.norm_mean = file.tensors.at("norm.mean").data;
  m.norm_std = file.tensors.at("norm.std").data;
  m.alpha_bar = file.tensors.at("diffusion.alpha_bar").data;
  for (std::size_t i = 0; i < m.norm_std.size(); ++i) {
    if (!(m.norm_std[i] > 0.0f)) fail(source, fmt::format("norm.std[{}] = {} must be > 0", i, m.norm_std[i]));
  }
  for (std::size_t t = 0; t < m.alpha_bar.size(); ++t) {
    const float a = m.alpha_bar[t];
    if (!(a > 0.0f && a < 1.0f)) fail(source, fmt::format("diffusion.alpha_bar[{}] = {} must be in (0, 1)", t, a));
    if (t > 0 && a > m.alpha_bar[t - 1]) {
      fail(source, fmt::format("diffusion.alpha_bar must not increase with t: [{}] = {} > [{}] = {}", t, a, t - 1, m.alpha_bar[t - 1]));
    }
  }
  m.metadata = std::move(file.metadata);
  m.tensors = std::move(file.tensors);
  return m;
}

std::shared_ptr<const Model> load_model(const std::filesystem::path& path) {
  const auto bytes = read_file_bytes(path);
  return std::make_shared<const Model>(parse_model(bytes, path.string()));
}

}  // namespace bodyd::inference
