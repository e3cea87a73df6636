// Model-file container decoder and model loader (docs/model-file.md).
#include "bodyd/inference/model_file.h"

#include "bodyd/inference/denoiser.h"
#include "bodyd/inference/features.h"

#include <fmt/format.h>
#include <fmt/ranges.h>
#include <nlohmann/json.hpp>

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
// Upper bound on any single config entry: keeps every size product far from overflow.
constexpr int kMaxConfigValue = 1 << 16;

using Json = nlohmann::json;

[[noreturn]] void fail(const std::string& source, const std::string& what) {
  throw ModelFileError(fmt::format("model file '{}': {}", source, what));
}

std::string shape_str(const std::vector<std::int64_t>& shape) { return fmt::format("[{}]", fmt::join(shape, ",")); }

std::uint64_t read_u64_le(const std::byte* p) {
  std::uint64_t v = 0;
  for (int i = 7; i >= 0; --i) v = (v << 8) | static_cast<std::uint64_t>(p[i]);
  return v;
}

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
  } catch (const Json::parse_error& e) {
    fail(source, fmt::format("metadata \"{}\" is not valid JSON ({})", key, e.what()));
  }
}

NetConfig parse_config(const std::string& source, const std::string& text) {
  const Json j = parse_meta_json(source, "config", text);
  if (!j.is_object()) fail(source, "metadata \"config\" must be a JSON object {W,D,E,H,L,TE,T}");
  NetConfig c;
  const std::pair<const char*, int*> keys[] = {{"W", &c.W}, {"D", &c.D},   {"E", &c.E}, {"H", &c.H},
                                               {"L", &c.L}, {"TE", &c.TE}, {"T", &c.T}};
  for (auto [key, dst] : keys) {
    auto it = j.find(key);
    if (it == j.end()) fail(source, fmt::format("config key \"{}\" is missing (config: {})", key, text));
    auto v = json_uint(*it, kMaxConfigValue);
    if (!v || *v < 1) {
      fail(source, fmt::format("config \"{}\" must be an integer in [1, {}], got {}", key, kMaxConfigValue, it->dump()));
    }
    *dst = static_cast<int>(*v);
  }
  if (c.TE % 2 != 0) fail(source, fmt::format("config \"TE\" must be even, got {}", c.TE));
  if (c.D != features::kDim) {
    fail(source, fmt::format("config \"D\" is {} but this build's features have kDim = {} (feature_version {}); "
                             "use a model trained for this version",
                             c.D, features::kDim, features::kVersion));
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

}  // namespace

TensorFile parse_tensor_file(std::span<const std::byte> bytes, const std::string& source) {
  if (bytes.size() < 8) {
    fail(source, fmt::format("truncated: {} bytes, shorter than the 8-byte header length", bytes.size()));
  }
  const std::uint64_t n = read_u64_le(bytes.data());
  if (n < 2 || n > kMaxHeaderBytes) {
    fail(source, fmt::format("header length {} is absurd (expected 2..{} bytes); not a model file or corrupt", n, kMaxHeaderBytes));
  }
  if (n > bytes.size() - 8) {
    fail(source, fmt::format("truncated: header length {} but only {} bytes follow the length field", n, bytes.size() - 8));
  }
  const auto* header_begin = reinterpret_cast<const char*>(bytes.data() + 8);
  Json header;
  try {
    header = Json::parse(header_begin, header_begin + n);
  } catch (const Json::parse_error& e) {
    fail(source, fmt::format("header JSON is malformed ({})", e.what()));
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
    auto where = [&](const std::string& what) { fail(source, fmt::format("tensor \"{}\": {}", name, what)); };
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
  return out;
}

namespace {
std::vector<std::byte> read_file_bytes(const std::filesystem::path& path) {
  std::error_code ec;
  if (!std::filesystem::exists(path, ec)) {
    throw ModelFileError(fmt::format("model file '{}': does not exist (pass a model with --model, or train one: docs/model-file.md)", path.string()));
  }
  if (!std::filesystem::is_regular_file(path, ec)) {
    throw ModelFileError(fmt::format("model file '{}': is not a regular file", path.string()));
  }
  std::ifstream in(path, std::ios::binary);
  if (!in) throw ModelFileError(fmt::format("model file '{}': cannot be opened for reading", path.string()));
  in.seekg(0, std::ios::end);
  const std::streamoff size = in.tellg();
  if (size < 0) throw ModelFileError(fmt::format("model file '{}': cannot determine its size", path.string()));
  in.seekg(0, std::ios::beg);
  std::vector<std::byte> bytes(static_cast<std::size_t>(size));
  if (size > 0 && !in.read(reinterpret_cast<char*>(bytes.data()), size)) {
    throw ModelFileError(fmt::format("model file '{}': read error", path.string()));
  }
  return bytes;
}
}  // namespace

TensorFile read_tensor_file(const std::filesystem::path& path) {
  const auto bytes = read_file_bytes(path);
  return parse_tensor_file(bytes, path.string());
}

std::vector<std::pair<std::string, std::vector<std::int64_t>>> expected_tensors(const NetConfig& c) {
  using Shape = std::vector<std::int64_t>;
  std::vector<std::pair<std::string, Shape>> v;
  // In 64 bits: config values are at most 2^16, so products like W * E cannot overflow.
  const std::int64_t W = c.W, D = c.D, E = c.E, H = c.H, TE = c.TE, T = c.T;
  auto linear = [&](const std::string& name, std::int64_t in, std::int64_t out) {
    v.emplace_back(name + ".weight", Shape{out, in});
    v.emplace_back(name + ".bias", Shape{out});
  };
  auto norm = [&](const std::string& name, std::int64_t n) {
    v.emplace_back(name + ".weight", Shape{n});
    v.emplace_back(name + ".bias", Shape{n});
  };
  linear("enc", 2 * D, E);
  linear("inp", W * E, H);
  linear("time1", TE, H);
  linear("time2", H, H);
  for (int b = 0; b < c.L; ++b) {
    const std::string p = fmt::format("blocks.{}.", b);
    norm(p + "norm", H);
    linear(p + "fc1", H, H);
    linear(p + "fc2", H, H);
  }
  norm("out_norm", H);
  linear("out", H, W * E);
  linear("dec1", 2 * E, E);
  linear("dec2", E, D);
  v.emplace_back("norm.mean", Shape{D});
  v.emplace_back("norm.std", Shape{D});
  v.emplace_back("diffusion.alpha_bar", Shape{T});
  return v;
}

const TensorF32& Model::tensor(std::string_view name) const {
  auto it = tensors.find(name);
  if (it == tensors.end()) throw ModelFileError(fmt::format("model file '{}': tensor \"{}\" is missing", source, name));
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
  const std::string& version = require_meta(source, file, "format_version");
  if (version != kModelFormatVersion) {
    fail(source, fmt::format("format_version \"{}\" is not supported (this build reads \"{}\"); use a matching bodyd or re-export the model",
                             version, kModelFormatVersion));
  }
  const std::string& arch = require_meta(source, file, "architecture");
  const Architecture* architecture = find_architecture(arch);
  if (architecture == nullptr) {
    fail(source, fmt::format("architecture \"{}\" is unknown (this build runs: {}); use a bodyd that knows it or a model "
                             "of a known architecture", arch, architecture_names()));
  }
  m.feature_version = parse_int_meta(source, "feature_version", require_meta(source, file, "feature_version"));
  if (m.feature_version != features::kVersion) {
    fail(source, fmt::format("feature_version {} does not match this build's features::kVersion {}; retrain or export the model "
                             "with the current features",
                             m.feature_version, features::kVersion));
  }
  m.config = parse_config(source, require_meta(source, file, "config"));
  m.skeleton = parse_skeleton(source, require_meta(source, file, "skeleton"));
  m.fps = parse_double_meta(source, "fps", require_meta(source, file, "fps"));
  if (m.fps <= 0.0) fail(source, fmt::format("metadata \"fps\" must be > 0, got {}", m.fps));
  m.provenance_json = require_meta(source, file, "provenance");
  if (!parse_meta_json(source, "provenance", m.provenance_json).is_object()) {
    fail(source, "metadata \"provenance\" must be a JSON object");
  }

  // Tensors: exactly the expected set, with exactly the expected shapes, all finite.
  const auto expected = architecture->expected_tensors(m.config);
  std::set<std::string, std::less<>> expected_names;
  for (const auto& [name, shape] : expected) {
    expected_names.insert(name);
    auto it = file.tensors.find(name);
    if (it == file.tensors.end()) fail(source, fmt::format("tensor \"{}\" (shape {}) is missing", name, shape_str(shape)));
    if (it->second.shape != shape) {
      fail(source, fmt::format("tensor \"{}\" has shape {}, expected {} for config W={} D={} E={} H={} L={} TE={} T={}", name,
                               shape_str(it->second.shape), shape_str(shape), m.config.W, m.config.D, m.config.E,
                               m.config.H, m.config.L, m.config.TE, m.config.T));
    }
    const auto& d = it->second.data;
    if (auto bad = std::find_if(d.begin(), d.end(), [](float x) { return !std::isfinite(x); }); bad != d.end()) {
      fail(source, fmt::format("tensor \"{}\" has a non-finite value ({}) at flat index {}", name, *bad, bad - d.begin()));
    }
  }
  for (const auto& [name, t] : file.tensors) {
    if (!expected_names.contains(name)) {
      fail(source, fmt::format("unexpected tensor \"{}\" (shape {}) for architecture {} with L={}", name, shape_str(t.shape),
                               arch, m.config.L));
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
