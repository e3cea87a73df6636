// Model-file loader: the valid fixture loads with the expected content; every kind of broken
// file (written to a temp dir from the valid fixture) fails with a ModelFileError naming the problem.
#include "bodyd/inference/denoiser.h"
#include "bodyd/inference/features.h"
#include "bodyd/inference/model_file.h"
#include "bodyd/motion/bvh.h"
#include "test_util.h"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>
#include <openssl/evp.h>
#include <sys/stat.h>

#include <cstring>
#include <fstream>
#include <functional>
#include <limits>
#include <unistd.h>

namespace bodyd::test {
namespace {

using inference::ModelFileError;
using Json = nlohmann::json;

std::vector<std::byte> read_bytes(const std::filesystem::path& p) {
  std::ifstream in(p, std::ios::binary);
  std::vector<char> c((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  std::vector<std::byte> b(c.size());
  std::memcpy(b.data(), c.data(), c.size());
  return b;
}

std::string sha256_hex(const std::vector<std::byte>& bytes) {
  unsigned char digest[32];
  unsigned int length = 0;
  EVP_Digest(bytes.data(), bytes.size(), digest, &length, EVP_sha256(), nullptr);
  std::string hex;
  for (unsigned char c : digest) {
    static const char* kDigits = "0123456789abcdef";
    hex += kDigits[c >> 4];
    hex += kDigits[c & 15];
  }
  return hex;
}

// The fixture split into its header JSON and data bytes, edited, and put back together.
struct Parts {
  Json header;
  std::vector<std::byte> data;

  static Parts of(const std::vector<std::byte>& bytes) {
    std::uint64_t n = 0;
    std::memcpy(&n, bytes.data(), 8);
    Parts p;
    p.header = Json::parse(reinterpret_cast<const char*>(bytes.data()) + 8, reinterpret_cast<const char*>(bytes.data()) + 8 + n);
    p.data.assign(bytes.begin() + 8 + static_cast<std::ptrdiff_t>(n), bytes.end());
    return p;
  }
  // Re-encodes the file. With `restamp` (the default) and a "checksum" in the metadata, the
  // checksum is computed again for the edited file (docs/model-file.md, "Checksum"), so a test
  // reaches the check it is about rather than the checksum.
  [[nodiscard]] std::vector<std::byte> bytes(bool restamp = true) const {
    Json h = header;
    const bool stamp = restamp && h.is_object() && h.contains("__metadata__") && h["__metadata__"].is_object() &&
                       h["__metadata__"].contains("checksum");
    const std::string zeros = "sha256:" + std::string(64, '0');
    if (stamp) h["__metadata__"]["checksum"] = zeros;
    std::string text = h.dump();
    std::vector<std::byte> out(8 + text.size() + data.size());
    const std::uint64_t n = text.size();
    std::memcpy(out.data(), &n, 8);
    if (stamp) {
      std::vector<std::byte> all = out;
      std::memcpy(all.data() + 8, text.data(), text.size());
      std::memcpy(all.data() + 8 + text.size(), data.data(), data.size());
      text.replace(text.find(zeros), zeros.size(), "sha256:" + sha256_hex(all));
    }
    std::memcpy(out.data() + 8, text.data(), text.size());
    std::memcpy(out.data() + 8 + text.size(), data.data(), data.size());
    return out;
  }
  Json& meta() { return header["__metadata__"]; }
  // Metadata value that is itself JSON, edited in place.
  void edit_meta_json(const std::string& key, const std::function<void(Json&)>& f) {
    Json j = Json::parse(meta()[key].get<std::string>());
    f(j);
    meta()[key] = j.dump();
  }
  float* floats(const std::string& tensor) {
    return reinterpret_cast<float*>(data.data() + header[tensor]["data_offsets"][0].get<std::size_t>());
  }
};

class ModelFileTest : public ::testing::Test {
 protected:
  void SetUp() override {
    valid_ = read_bytes(tiny_model_path());
    ASSERT_GT(valid_.size(), 1000u) << tiny_model_path();
    dir_ = std::filesystem::temp_directory_path() / ("bodyd_model_file_test_" + std::to_string(::getpid()));
    std::filesystem::create_directories(dir_);
  }
  void TearDown() override { std::filesystem::remove_all(dir_); }

  std::filesystem::path write(const std::vector<std::byte>& bytes, const std::string& name = "broken.safetensors") {
    const auto p = dir_ / name;
    std::ofstream out(p, std::ios::binary | std::ios::trunc);
    out.write(reinterpret_cast<const char*>(bytes.data()), static_cast<std::streamsize>(bytes.size()));
    return p;
  }

  // Loading `bytes` from a file must throw a ModelFileError mentioning the file and every `needles`.
  void expect_error(const std::vector<std::byte>& bytes, std::initializer_list<std::string> needles) {
    const auto p = write(bytes);
    try {
      auto m = inference::load_model(p);
      ADD_FAILURE() << "loaded a broken file; expected an error mentioning " << *needles.begin();
    } catch (const ModelFileError& e) {
      const std::string msg = e.what();
      EXPECT_NE(msg.find(p.string()), std::string::npos) << msg;
      for (const auto& n : needles) EXPECT_NE(msg.find(n), std::string::npos) << "'" << n << "' not in: " << msg;
    }
  }
  void expect_error(const Parts& p, std::initializer_list<std::string> needles) { expect_error(p.bytes(), needles); }
  // expect_error for the valid file with its metadata entry `key` set to `value`.
  void expect_error_with_meta(const std::string& key, const Json& value, std::initializer_list<std::string> needles) {
    Parts p = parts();
    p.meta()[key] = value;
    expect_error(p, needles);
  }
  // expect_error for the valid file without its metadata entry `key`.
  void expect_error_without_meta(const std::string& key, std::initializer_list<std::string> needles) {
    Parts p = parts();
    p.meta().erase(key);
    expect_error(p, needles);
  }

  Parts parts() const { return Parts::of(valid_); }

  std::vector<std::byte> valid_;
  std::filesystem::path dir_;
};

TEST_F(ModelFileTest, ValidFixtureLoads) {
  const auto m = inference::load_model(tiny_model_path());
  // The config holds the fields of mlpwin-v1's row, in the row's order.
  const std::vector<std::pair<std::string, int>> config = {{"W", 4},  {"D", features::kDim}, {"E", 8}, {"H", 16},
                                                           {"L", 1},  {"TE", 64},            {"T", 10}};
  EXPECT_EQ(m->config.values(), config);
  EXPECT_EQ(m->config.frames(), 4);
  EXPECT_EQ(m->config.dim(), features::kDim);
  EXPECT_EQ(m->config.steps(), 10);
  EXPECT_EQ(m->feature_version, features::kVersion);
  EXPECT_DOUBLE_EQ(m->fps, 30.0);
  ASSERT_EQ(m->skeleton.size(), 22);
  EXPECT_EQ(m->skeleton.names[5], "Head");
  EXPECT_EQ(m->skeleton.parents[0], -1);
  EXPECT_EQ(m->skeleton.names[9], "Hand_L");
  // Hips' rest offset from tests/data/walk_60.bvh (centimetres there): (-0.726466, 93.3139, -2.00062).
  EXPECT_NEAR(m->skeleton.offsets[1].y(), 0.933139, 1e-6);
  // The whole skeleton equals the one the C++ BVH reader gives for the same file.
  const Motion bvh = read_bvh(fixtures() / "walk_60.bvh");
  ASSERT_EQ(bvh.skeleton.size(), 22);
  for (int j = 0; j < 22; ++j) {
    const auto u = static_cast<std::size_t>(j);
    EXPECT_EQ(m->skeleton.names[u], bvh.skeleton.names[u]);
    EXPECT_EQ(m->skeleton.parents[u], bvh.skeleton.parents[u]);
    EXPECT_LT((m->skeleton.offsets[u] - bvh.skeleton.offsets[u]).norm(), 1e-9) << bvh.skeleton.names[u];
  }
  EXPECT_EQ(m->norm_mean.size(), 191u);
  EXPECT_EQ(m->norm_std.size(), 191u);
  ASSERT_EQ(m->alpha_bar.size(), 10u);
  // cosine schedule, T = 10: alpha_bar[9] is clipped to 1e-5; alpha_bar[0] = f(0.1) / f(0).
  EXPECT_FLOAT_EQ(m->alpha_bar[9], 1e-5f);
  const double f0 = std::pow(std::cos(0.008 / 1.008 * M_PI / 2), 2);
  EXPECT_NEAR(m->alpha_bar[0], std::pow(std::cos(0.108 / 1.008 * M_PI / 2), 2) / f0, 1e-6);
  EXPECT_TRUE(Json::parse(m->provenance_json).is_object());
  EXPECT_EQ(m->tensor("blocks.0.fc1.weight").shape, (std::vector<std::int64_t>{16, 16}));
  EXPECT_THROW((void)m->tensor("blocks.1.fc1.weight"), ModelFileError);
}

TEST_F(ModelFileTest, ReencodedFixtureStillLoads) {
  // Guards the editing helpers: an unedited round trip through Parts must load.
  const auto p = write(parts().bytes());
  EXPECT_NO_THROW((void)inference::load_model(p));
}

TEST_F(ModelFileTest, ExpectedTensorsMatchTheFile) {
  const auto m = inference::load_model(tiny_model_path());
  const auto* arch = inference::find_architecture(m->metadata.at("architecture"));
  ASSERT_NE(arch, nullptr);
  const auto expected = inference::expected_tensors(*arch, m->config);
  EXPECT_EQ(expected.size(), m->tensors.size());
  // 4 + 4 + 2*2 linears + 1 block * (norm + 2 linears) + out_norm + 3 linears = 17 pairs + 3 = ... count by hand:
  // enc, inp, time1, time2 (8) + blocks.0.{norm,fc1,fc2} (6) + out_norm, out, dec1, dec2 (8) + norm.mean/std, alpha_bar (3).
  EXPECT_EQ(expected.size(), 25u);
}

TEST_F(ModelFileTest, MissingFile) {
  try {
    (void)inference::load_model(dir_ / "nope.safetensors");
    FAIL();
  } catch (const ModelFileError& e) {
    EXPECT_NE(std::string(e.what()).find("does not exist"), std::string::npos) << e.what();
  }
}

TEST_F(ModelFileTest, EmptyAndShortFiles) {
  expect_error(std::vector<std::byte>{}, {"truncated"});
  expect_error(std::vector<std::byte>(valid_.begin(), valid_.begin() + 5), {"truncated"});
}

TEST_F(ModelFileTest, TruncatedInHeader) {
  expect_error(std::vector<std::byte>(valid_.begin(), valid_.begin() + 100), {"truncated", "header length"});
}

TEST_F(ModelFileTest, TruncatedInData) {
  expect_error(std::vector<std::byte>(valid_.begin(), valid_.end() - 4), {"truncated", "diffusion.alpha_bar"});
}

TEST_F(ModelFileTest, AbsurdHeaderLength) {
  auto b = valid_;
  const std::uint64_t huge = std::uint64_t{1} << 40;
  std::memcpy(b.data(), &huge, 8);
  expect_error(b, {"header length", "not a bodyd model file"});
  const std::uint64_t tiny = 0;
  std::memcpy(b.data(), &tiny, 8);
  expect_error(b, {"header length", "not a bodyd model file"});
}

TEST_F(ModelFileTest, MalformedJson) {
  auto b = valid_;
  b[8] = std::byte{'['};  // the header's opening brace
  b[9] = std::byte{','};
  expect_error(b, {"malformed"});
  Parts p = parts();
  p.header = Json::array({1, 2});
  expect_error(p, {"must be an object"});
}

TEST_F(ModelFileTest, WrongFormat) {
  expect_error_with_meta("format", "gguf", {"\"format\"", "gguf"});
  expect_error_without_meta("format", {"\"format\" is missing"});
}

TEST_F(ModelFileTest, WrongFormatVersion) {
  expect_error_with_meta("format_version", "2", {"format_version", "\"2\""});
}

TEST_F(ModelFileTest, UnknownArchitecture) {
  expect_error_with_meta("architecture", "transformer-v9", {"architecture", "transformer-v9"});
}

TEST_F(ModelFileTest, FeatureVersionMismatch) {
  const std::string next = std::to_string(features::kVersion + 1);
  expect_error_with_meta("feature_version", next, {"feature_version", next});
  expect_error_with_meta("feature_version", "one", {"feature_version", "integer"});
}

TEST_F(ModelFileTest, ConfigProblems) {
  Parts p = parts();
  p.edit_meta_json("config", [](Json& j) { j.erase("H"); });
  expect_error(p, {"config key \"H\" is missing"});
  p = parts();
  p.edit_meta_json("config", [](Json& j) { j["D"] = 190; });
  expect_error(p, {"\"D\" is 190", "kDim"});
  p = parts();
  p.edit_meta_json("config", [](Json& j) { j["W"] = -4; });
  expect_error(p, {"\"W\" must be an integer"});
  p = parts();
  p.edit_meta_json("config", [](Json& j) { j["TE"] = 63; });
  expect_error(p, {"\"TE\" must be even"});
  expect_error_with_meta("config", "{W: 4", {"\"config\" is not valid JSON"});
  p = parts();
  // A config that disagrees with the tensors: the first tensor whose shape follows H is named.
  p.edit_meta_json("config", [](Json& j) { j["H"] = 32; });
  expect_error(p, {"inp.weight", "[16,32]", "expected [32,32]"});
}

// The loader checks a file against its architecture's row, whichever row: tcn-v1's fields
// (its R limited to 16 by the row) and tensors are named like mlpwin-v1's.
TEST_F(ModelFileTest, TcnFilesAreCheckedAgainstTheirRow) {
  const Parts tcn = Parts::of(read_bytes(fixtures() / "tiny_tcn.safetensors"));
  EXPECT_NO_THROW((void)inference::load_model(write(tcn.bytes(), "tcn.safetensors")));
  Parts p = tcn;
  p.edit_meta_json("config", [](Json& j) { j.erase("K"); });
  expect_error(p, {"config key \"K\" is missing"});
  p = tcn;
  p.edit_meta_json("config", [](Json& j) { j["R"] = 17; });
  expect_error(p, {"config \"R\" must be an integer in [1, 16], got 17"});
  p = tcn;
  p.edit_meta_json("config", [](Json& j) { j["K"] = 2; });
  expect_error(p, {"blocks.0.conv.weight", "[16,16,3]", "expected [16,16,2]", "for config W=10 D=191 C=16 K=2"});
  p = tcn;
  p.edit_meta_json("config", [](Json& j) { j["L"] = 2; });
  expect_error(p, {"unexpected tensor", "blocks.2.", "tcn-v1", "L=2"});
  // A tcn-v1 config under the mlpwin-v1 name: mlpwin-v1's fields are asked for.
  p = tcn;
  p.meta()["architecture"] = "mlpwin-v1";
  expect_error(p, {"config key \"E\" is missing"});
}

TEST_F(ModelFileTest, TensorShapeChanged) {
  Parts p = parts();
  p.header["blocks.0.fc1.weight"]["shape"] = Json::array({256});  // same byte count, wrong shape
  expect_error(p, {"blocks.0.fc1.weight", "[256]", "expected [16,16]"});
  p = parts();
  p.header["blocks.0.fc1.weight"]["shape"] = Json::array({16, 15});  // byte count no longer matches
  expect_error(p, {"blocks.0.fc1.weight", "needs 960"});
}

TEST_F(ModelFileTest, WrongDtype) {
  Parts p = parts();
  p.header["dec2.bias"]["dtype"] = "F16";
  expect_error(p, {"dec2.bias", "F16", "not supported"});
}

TEST_F(ModelFileTest, MissingTensor) {
  Parts p = parts();
  p.header.erase("time2.weight");
  expect_error(p, {"\"time2.weight\"", "missing"});
  p = parts();
  p.header.erase("norm.std");
  expect_error(p, {"\"norm.std\"", "missing"});
}

TEST_F(ModelFileTest, UnexpectedTensor) {
  Parts p = parts();
  const std::size_t end = p.data.size();
  p.data.resize(end + 16);
  p.header["blocks.1.fc1.bias"] = {{"dtype", "F32"}, {"shape", {4}}, {"data_offsets", {end, end + 16}}};
  expect_error(p, {"unexpected tensor", "blocks.1.fc1.bias"});
}

TEST_F(ModelFileTest, OffsetsOutsideOrOverlapping) {
  Parts p = parts();
  const auto size = p.data.size();
  p.header["dec2.bias"]["data_offsets"] = {size - 4, size + 760};
  expect_error(p, {"dec2.bias", "past the end"});
  p = parts();
  p.header["norm.std"]["data_offsets"] = p.header["norm.mean"]["data_offsets"];
  expect_error(p, {"overlap", "norm.mean", "norm.std"});
  p = parts();
  p.header["enc.bias"]["data_offsets"] = {8, 0};
  expect_error(p, {"enc.bias", "data_offsets"});
  p = parts();
  p.header["enc.bias"]["data_offsets"] = {-8, 24};
  expect_error(p, {"enc.bias", "data_offsets"});
}

TEST_F(ModelFileTest, OverlapBehindAnEmptyOrSmallTensorIsFound) {
  // A large tensor followed (in offset order) by an unrelated one and then one inside the first.
  Parts p = parts();
  const auto inp = p.header["inp.weight"]["data_offsets"];
  const std::size_t b = inp[0].get<std::size_t>();
  p.header["dec1.bias"]["data_offsets"] = {b + 4, b + 4 + 32};   // inside inp.weight
  p.header["enc.bias"]["data_offsets"] = {b + 100, b + 100 + 32};  // also inside
  expect_error(p, {"overlap", "inp.weight"});
}

TEST_F(ModelFileTest, MetadataNotStrings) {
  expect_error_with_meta("fps", 30, {"\"fps\" must be a string"});
  expect_error_with_meta("fps", "-30", {"fps", "> 0"});
  expect_error_without_meta("provenance", {"\"provenance\" is missing"});
}

TEST_F(ModelFileTest, BadSkeleton) {
  expect_error_with_meta("skeleton", "{\"names\": [", {"\"skeleton\" is not valid JSON"});
  Parts p = parts();
  p.edit_meta_json("skeleton", [](Json& j) {
    for (const char* k : {"names", "parents", "offsets_m"}) j[k].erase(j[k].size() - 1);
  });
  expect_error(p, {"skeleton", "21 entries", "22 joints"});
  p = parts();
  p.edit_meta_json("skeleton", [](Json& j) { j["parents"][3] = 5; });
  expect_error(p, {"skeleton", "parents[3] = 5"});
  p = parts();
  p.edit_meta_json("skeleton", [](Json& j) { j["parents"][0] = 0; });
  expect_error(p, {"skeleton", "parents[0]"});
  p = parts();
  p.edit_meta_json("skeleton", [](Json& j) { j["offsets_m"][4] = Json::array({0.0, "x", 0.0}); });
  expect_error(p, {"skeleton", "offsets_m[4][1]"});
  p = parts();
  p.edit_meta_json("skeleton", [](Json& j) { j["names"][5] = "Noggin"; });
  expect_error(p, {"skeleton", "Noggin"});
  p = parts();
  p.edit_meta_json("skeleton", [](Json& j) { j["names"][6] = "Head"; });
  expect_error(p, {"skeleton", "\"Head\" appears twice"});
  p = parts();
  p.edit_meta_json("skeleton", [](Json& j) { j.erase("offsets_m"); });
  expect_error(p, {"skeleton", "\"offsets_m\" must be an array"});
}

TEST_F(ModelFileTest, BadValues) {
  Parts p = parts();
  p.floats("norm.std")[7] = 0.0f;
  expect_error(p, {"norm.std[7]", "> 0"});
  p = parts();
  p.floats("norm.std")[3] = -1.0f;
  expect_error(p, {"norm.std[3]"});
  p = parts();
  p.floats("blocks.0.fc2.weight")[11] = std::numeric_limits<float>::quiet_NaN();
  expect_error(p, {"blocks.0.fc2.weight", "non-finite", "11"});
  p = parts();
  p.floats("norm.mean")[0] = std::numeric_limits<float>::infinity();
  expect_error(p, {"norm.mean", "non-finite"});
  p = parts();
  p.floats("diffusion.alpha_bar")[2] = 1.5f;
  expect_error(p, {"alpha_bar[2]", "(0, 1)"});
  p = parts();
  std::swap(p.floats("diffusion.alpha_bar")[2], p.floats("diffusion.alpha_bar")[3]);
  expect_error(p, {"alpha_bar", "increase"});
}

// Issue 11, item 5: silent corruption is caught by the checksum, and the error names what changed.
TEST_F(ModelFileTest, ChecksumNamesTheTensorWhoseBytesChanged) {
  Parts p = parts();
  const auto offset = 8 + (valid_.size() - p.data.size() - 8) + p.header["inp.weight"]["data_offsets"][0].get<std::size_t>();
  auto b = valid_;
  b[offset + 4 * 5 + 3] ^= std::byte{0x20};  // one exponent bit of inp.weight[5]: still finite
  expect_error(b, {"checksum mismatch", "tensor \"inp.weight\"", "corrupt"});
}

TEST_F(ModelFileTest, ChecksumNamesTheHeaderWhenMetadataChanged) {
  // fps "30" -> "90" in place: same length, valid JSON, a plausible value.
  auto b = valid_;
  const std::string needle = "\"fps\":\"30\"";
  const std::string text(reinterpret_cast<const char*>(b.data()), b.size());
  const auto at = text.find(needle);
  ASSERT_NE(at, std::string::npos);
  b[at + needle.size() - 3] = std::byte{'9'};
  expect_error(b, {"checksum mismatch", "header", "fps"});
}

TEST_F(ModelFileTest, ModelWithoutChecksumIsRefusedWithTheFix) {
  Parts p = parts();
  p.meta().erase("checksum");
  p.meta().erase("tensor_checksums");
  expect_error(p.bytes(false), {"\"checksum\" is missing", "--restamp"});
  p = parts();
  p.meta()["checksum"] = "md5:1234";
  expect_error(p.bytes(false), {"\"checksum\" must be"});
}

TEST_F(ModelFileTest, TrailingBytesAreRefused) {
  auto b = valid_;
  b.resize(b.size() + 600, std::byte{0});
  expect_error(b, {"600 bytes after the end of the last tensor", "trailing"});
  // The same through the pure decoder (bytes in memory).
  try {
    (void)inference::parse_model(b, "mem");
    ADD_FAILURE();
  } catch (const ModelFileError& e) {
    EXPECT_NE(std::string(e.what()).find("trailing"), std::string::npos) << e.what();
  }
}

// Issue 11, item 4: a file that is not a model is refused from its first 8 bytes, its size is
// checked before anything else is read, and no error quotes the file's bytes.
TEST_F(ModelFileTest, NotAModelNeverEchoesItsBytesAndHugeFilesAreNotRead) {
  const std::string secret = "root:$6$Xsecretsalt$hash:19000:0:99999:7:::\n";
  std::vector<std::byte> b(secret.size());
  std::memcpy(b.data(), secret.data(), secret.size());
  const auto p = write(b, "shadow");
  std::uint64_t as_length = 0;
  std::memcpy(&as_length, secret.data(), 8);
  try {
    (void)inference::load_model(p);
    ADD_FAILURE();
  } catch (const ModelFileError& e) {
    const std::string msg = e.what();
    EXPECT_EQ(msg.find("root"), std::string::npos) << msg;
    EXPECT_EQ(msg.find("secret"), std::string::npos) << msg;
    EXPECT_EQ(msg.find(std::to_string(as_length)), std::string::npos) << msg;
    EXPECT_NE(msg.find("not a bodyd model file"), std::string::npos) << msg;
  }
  // A JSON-looking header is not quoted either.
  const std::string json_like = std::string("\x10\0\0\0\0\0\0\0{\"pw\":hunter2!!}");
  b.assign(json_like.size(), std::byte{0});
  std::memcpy(b.data(), json_like.data(), json_like.size());
  try {
    (void)inference::load_model(write(b, "json_like"));
    ADD_FAILURE();
  } catch (const ModelFileError& e) {
    EXPECT_EQ(std::string(e.what()).find("hunter2"), std::string::npos) << e.what();
  }
  // A sparse 3 GiB file (no disk space used) is refused by its size, not read.
  const auto big = dir_ / "big";
  { std::ofstream(big, std::ios::binary) << "x"; }
  std::filesystem::resize_file(big, std::uintmax_t{3} << 30);
  try {
    (void)inference::load_model(big);
    ADD_FAILURE();
  } catch (const ModelFileError& e) {
    EXPECT_NE(std::string(e.what()).find("more than"), std::string::npos) << e.what();
  }
  // A directory says so.
  try {
    (void)inference::load_model(dir_);
    ADD_FAILURE();
  } catch (const ModelFileError& e) {
    EXPECT_NE(std::string(e.what()).find("is a directory"), std::string::npos) << e.what();
    EXPECT_EQ(std::string(e.what()).find("train"), std::string::npos) << e.what();
  }
}

TEST_F(ModelFileTest, ContainerDecoderReadsAnyNames) {
  // The io fixture uses the same container with other tensor names; only the model layer rejects it.
  const auto io = inference::read_tensor_file(tiny_io_path());
  EXPECT_TRUE(io.metadata.contains("cases"));
  EXPECT_EQ(io.tensors.at("forward.0.x").shape, (std::vector<std::int64_t>{4, 191}));
  try {
    (void)inference::load_model(tiny_io_path());
    FAIL();
  } catch (const ModelFileError& e) {
    EXPECT_NE(std::string(e.what()).find("\"format\" is missing"), std::string::npos) << e.what();
  }
}

TEST_F(ModelFileTest, RandomCorruptionNeverCrashes) {
  // Flip bytes all over the file: every outcome is a ModelFileError naming the source, or (a
  // flip that rewrote a byte with its own value, or one the checksum does not cover) a load of
  // exactly the original model: the checksum lets nothing else through.
  const inference::Model original = inference::parse_model(valid_, "original");
  int rejected = 0;
  std::mt19937 rng(3);
  for (int trial = 0; trial < 300; ++trial) {
    auto b = valid_;
    const int flips = 1 + static_cast<int>(rng() % 4);
    for (int f = 0; f < flips; ++f) {
      const std::size_t at = trial % 2 == 0 ? rng() % std::min<std::size_t>(b.size(), 4096) : rng() % b.size();
      b[at] = static_cast<std::byte>(rng() & 0xff);
    }
    if (trial % 7 == 0) b.resize(rng() % b.size());
    try {
      const inference::Model m = inference::parse_model(b, "corrupt");
      EXPECT_EQ(m.metadata, original.metadata) << trial;
      ASSERT_EQ(m.tensors.size(), original.tensors.size()) << trial;
      for (const auto& [name, t] : original.tensors) {
        ASSERT_TRUE(m.tensors.contains(name)) << trial << " " << name;
        EXPECT_EQ(m.tensors.at(name).shape, t.shape) << trial << " " << name;
        EXPECT_EQ(m.tensors.at(name).data, t.data) << trial << " " << name;
      }
    } catch (const ModelFileError& e) {
      ++rejected;
      const std::string msg = e.what();
      EXPECT_NE(msg.find("corrupt"), std::string::npos) << trial << ": " << msg;
      EXPECT_GT(msg.size(), std::string("corrupt: ").size()) << trial << ": " << msg;
    }
  }
  EXPECT_GT(rejected, 250);
}

}  // namespace
}  // namespace bodyd::test
