// The architecture table (denoiser.h): one row per network this build runs.
#include "bodyd/inference/denoiser.h"

#include "bodyd/base/require.h"
#include "bodyd/inference/mlpwin.h"
#include "bodyd/inference/tcn.h"
#include "bodyd/inference/tcnmlp.h"

#include <fmt/format.h>

#include <algorithm>
#include <array>

namespace bodyd::inference {
namespace {

constexpr std::array kArchitectures = {
    Architecture{kArchitectureMlpWin, MlpWin::kConfigFields, &MlpWin::tensors, &MlpWin::make},
    Architecture{kArchitectureTcn, Tcn::kConfigFields, &Tcn::tensors, &Tcn::make},
    Architecture{kArchitectureTcnMlp, TcnMlp::kConfigFields, &TcnMlp::tensors, &TcnMlp::make},
};

}  // namespace

std::span<const Architecture> architectures() { return kArchitectures; }

const Architecture* find_architecture(std::string_view name) {
  const auto a = std::ranges::find(kArchitectures, name, &Architecture::name);
  return a == kArchitectures.end() ? nullptr : &*a;
}

std::string architecture_names() {
  std::string out;
  for (const Architecture& a : kArchitectures) {
    if (!out.empty()) out += ", ";
    out += a.name;
  }
  return out;
}

TensorShapes expected_tensors(const Architecture& arch, const ModelConfig& config) {
  TensorShapes v = arch.tensors(config);
  const std::int64_t D = config.dim(), T = config.steps();
  v.emplace_back("norm.mean", std::vector<std::int64_t>{D});
  v.emplace_back("norm.std", std::vector<std::int64_t>{D});
  v.emplace_back("diffusion.alpha_bar", std::vector<std::int64_t>{T});
  return v;
}

std::string_view weights_name(Weights weights) { return weights == Weights::bf16 ? "bf16" : "f32"; }

std::optional<Weights> parse_weights(std::string_view name) {
  if (name == "f32") return Weights::f32;
  if (name == "bf16") return Weights::bf16;
  return std::nullopt;
}

std::shared_ptr<const Denoiser> make_denoiser(const Model& model, Weights weights) {
  const auto it = model.metadata.find("architecture");
  const std::string name = it == model.metadata.end() ? std::string() : it->second;
  const Architecture* arch = find_architecture(name);
  if (arch == nullptr) {
    throw ModelFileError(
        fmt::format("model file '{}'", model.source),
        fmt::format("architecture \"{}\" is unknown (this build runs: {})", name, architecture_names()),
        "use a bodyd that knows it or a model of a known architecture");
  }
  return arch->make(model, weights);
}

void Denoiser::forward_newest(std::span<const float> x, std::span<const float> m, int t, std::span<float> out,
                              DenoiserScratch& scratch) const {
  (void)x, (void)m, (void)t, (void)out, (void)scratch;
  BODYD_REQUIRE(false, "forward_newest: this architecture has no newest-frame pass (computes_newest_alone() is false)");
}

}  // namespace bodyd::inference
