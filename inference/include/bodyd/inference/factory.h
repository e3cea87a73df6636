// Makes a Reconstructor by method name: the one place the daemon, the evaluation and the
// tools turn "ik" or "diffusion" into an object.
#pragma once

#include "bodyd/base/user_error.h"
#include "bodyd/inference/denoiser.h"
#include "bodyd/inference/one_euro.h"
#include "bodyd/inference/reconstructor.h"

#include <cstdint>
#include <filesystem>
#include <memory>
#include <optional>
#include <stdexcept>
#include <string>
#include <string_view>
#include <vector>

namespace bodyd {

// A reconstructor could not be made (unknown method, missing or bad model file, missing
// skeleton); the message says which and what to do.
class ReconstructorError : public UserError {
 public:
  using UserError::UserError;
};

// The method names make_reconstructor() knows, e.g. {"diffusion", "ik"}.
[[nodiscard]] std::vector<std::string> known_methods();

// Method options (ignored by methods they do not apply to).
struct ReconstructorOptions {
  int diffusion_steps = 2;      // DDIM steps K (docs/models.md)
  float guidance = 1.0f;        // classifier-free guidance scale (1 = off)
  std::optional<inference::Weights> weights;  // the network's online weights (unset: DiffusionOptions' default)
  std::uint64_t seed = 1;       // the diffusion's noise
  OneEuroOptions filter;        // the diffusion's tracker filter (one_euro.h; the daemon's "filter" keys)
  BodyFilterOptions body_filter;  // the diffusion's body filter (one_euro.h; the daemon's "body_filter" keys)
  // The diffusion's foot lock (DiffusionOptions' fields of these names, diffusion.h); unset:
  // DiffusionOptions' defaults (bodyd-eval's --contact-on, ... flags).
  std::optional<float> contact_on, contact_off;
  std::optional<double> foot_contact_speed_m_s, foot_unlock_distance_m, foot_release_half_life_s;
  std::optional<double> elbow_pole_bias_m;  // the arms' elbow pole (DiffusionOptions; bodyd-eval's --elbow-pole-bias-m)
  std::optional<double> leg_position_blend;  // the legs (DiffusionOptions; bodyd-eval's --leg-position-blend)
};

// method "ik": the fixed-rule baseline (ik.h) on `skeleton_hint` (required; model_path unused).
// method "diffusion": the diffusion reconstructor loaded from `model_path`.
// `skeleton_hint` is the skeleton of the data at hand (e.g. the clip being evaluated), or null.
// Throws ReconstructorError.
[[nodiscard]] std::unique_ptr<Reconstructor> make_reconstructor(std::string_view method,
                                                                 const std::filesystem::path& model_path,
                                                                 const Skeleton* skeleton_hint,
                                                                 const ReconstructorOptions& options = {});

// The same with the model file already loaded (load_reconstructor_model), for a caller that
// makes many reconstructors of one model (bodyd-eval: one per clip). `model` may be null for
// methods that need none.
[[nodiscard]] std::unique_ptr<Reconstructor> make_reconstructor_of(std::string_view method,
                                                                    std::shared_ptr<const inference::Model> model,
                                                                    const Skeleton* skeleton_hint,
                                                                    const ReconstructorOptions& options = {});

// Reads and verifies a model file (inference::load_model); throws ReconstructorError saying
// what is wrong with it.
[[nodiscard]] std::shared_ptr<const inference::Model> load_reconstructor_model(const std::filesystem::path& model_path);

}  // namespace bodyd
