// Model files (docs/model-file.md): the safetensors container layout holding a bodyd model.
//
//   [8 bytes]  N, little-endian uint64: length of the JSON header
//   [N bytes]  JSON: {tensor name: {"dtype": "F32", "shape": [...], "data_offsets": [begin, end]},
//                     "__metadata__": {string: string}}
//   [rest]     the tensors' raw little-endian bytes; offsets are relative to the end of the header
//
// Two layers: a generic container decoder (parse_tensor_file: any tensor names, F32 only) and the
// model loader (parse_model / load_model), which checks everything a "bodyd-model" file must hold
// and names what is wrong. What a file of one architecture holds (its config fields and tensors) is
// that architecture's row of the table in denoiser.h; this layer knows no architecture. Loading allocates and may throw
// ModelFileError; it happens once at start-up, never in the real-time loop. The loaded Model is
// immutable and meant to be shared (std::shared_ptr<const Model>) by every session.
#pragma once

#include "bodyd/base/user_error.h"
#include "bodyd/motion/skeleton.h"

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <map>
#include <initializer_list>
#include <memory>
#include <optional>
#include <span>
#include <stdexcept>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

namespace bodyd::inference {

// Every problem with a model file: the message names the file, the field or tensor, what is
// wrong and, where it helps, what to do.
class ModelFileError : public UserError {
 public:
  using UserError::UserError;
};

inline constexpr std::string_view kModelFormat = "bodyd-model";
inline constexpr std::string_view kModelFormatVersion = "1";
inline constexpr int kModelSkeletonJoints = 22;
// Metadata keys of the checksum (docs/model-file.md, "Checksum"): "sha256:" and 64 hex digits
// of the length field, the header (with those digits as '0's) and the data; and a JSON object
// tensor name -> "sha256:..." of that tensor's bytes, to name the tensor that changed.
inline constexpr std::string_view kChecksumKey = "checksum";
inline constexpr std::string_view kTensorChecksumsKey = "tensor_checksums";

// One tensor of the container, row-major, float32.
struct TensorF32 {
  std::vector<std::int64_t> shape;
  std::vector<float> data;
};

// The decoded container: no checks beyond the container's own layout.
struct TensorFile {
  std::map<std::string, TensorF32, std::less<>> tensors;
  std::map<std::string, std::string, std::less<>> metadata;
};

// Pure decoder. Checks: header length, JSON syntax, each entry's dtype ("F32" only), shape,
// offsets (inside the data, length = 4 * product(shape), no two tensors overlapping, no bytes
// after the last tensor), metadata being string -> string, and the checksum when the metadata
// has one (a mismatch names the tensor or the header that changed). Messages never quote the
// file's bytes beyond its JSON header's fields. `source_name` is used in messages. Throws
// ModelFileError. read_tensor_file checks the file's size against its header before reading
// the data (at most 2 GiB).
[[nodiscard]] TensorFile parse_tensor_file(std::span<const std::byte> bytes, const std::string& source_name);
[[nodiscard]] TensorFile read_tensor_file(const std::filesystem::path& path);

// The config keys every architecture has (docs/model-file.md, "Metadata"): frames per window,
// features per frame (== features::kDim) and diffusion steps (== the length of diffusion.alpha_bar).
inline constexpr std::string_view kConfigFrames = "W";
inline constexpr std::string_view kConfigFeatures = "D";
inline constexpr std::string_view kConfigSteps = "T";
// Upper bound on any config value: keeps every size product far from overflow.
inline constexpr int kMaxConfigValue = 1 << 16;

// The integer hyper-parameters of metadata "config" (each in [1, 65536]), in the order the
// architecture's row lists them (denoiser.h, Architecture::config). The loader checks them against
// that row; what they mean beyond W, D and T is the architecture's business.
class ModelConfig {
 public:
  ModelConfig() = default;
  ModelConfig(std::initializer_list<std::pair<std::string, int>> values);

  // The value of `key`, or nullopt.
  [[nodiscard]] std::optional<int> find(std::string_view key) const;
  // The value of `key`; throws ModelFileError when absent (cannot happen for a key of the row of
  // a checked model).
  [[nodiscard]] int at(std::string_view key) const;
  void set(std::string_view key, int value);  // replaces or appends
  [[nodiscard]] const std::vector<std::pair<std::string, int>>& values() const { return values_; }
  [[nodiscard]] int frames() const { return at(kConfigFrames); }
  [[nodiscard]] int dim() const { return at(kConfigFeatures); }
  [[nodiscard]] int steps() const { return at(kConfigSteps); }
  // "W=4 D=191 E=8 ..." for messages.
  [[nodiscard]] std::string to_string() const;

 private:
  std::vector<std::pair<std::string, int>> values_;
};

// Tensor names with their shapes, in file order.
using TensorShapes = std::vector<std::pair<std::string, std::vector<std::int64_t>>>;

// A loaded, fully checked model. Immutable after loading.
struct Model {
  std::string source;                // where it was loaded from (for messages)
  ModelConfig config;                // metadata "config": the fields of its architecture's row (denoiser.h)
  int feature_version = 0;           // == features::kVersion
  double fps = 0.0;                  // frame rate of the windows
  Skeleton skeleton;                 // 22 joints, metres (the training data's skeleton)
  std::string provenance_json;       // free-form JSON object: data, split, steps, hardware, commit...
  std::vector<float> norm_mean;      // D: features are normalised as (f - mean) / std
  std::vector<float> norm_std;       // D, every entry finite and > 0
  std::vector<float> alpha_bar;      // T, diffusion.alpha_bar: in (0, 1), non-increasing in t
  std::map<std::string, std::string, std::less<>> metadata;  // every metadata entry, as stored
  std::map<std::string, TensorF32, std::less<>> tensors;     // every tensor, by name

  // The tensor `name`; throws ModelFileError when absent (cannot happen for a tensor the
  // architecture's row names).
  [[nodiscard]] const TensorF32& tensor(std::string_view name) const;
};

// Decodes and checks a model file (see docs/model-file.md, "What the loader checks"); a model
// must carry a checksum. Throws ModelFileError naming `source_name` and the first problem found.
[[nodiscard]] Model parse_model(std::span<const std::byte> bytes, const std::string& source_name);
// Reads `path` and parses it; a missing or unreadable file is a ModelFileError too.
[[nodiscard]] std::shared_ptr<const Model> load_model(const std::filesystem::path& path);

}  // namespace bodyd::inference
