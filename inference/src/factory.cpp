#include "bodyd/inference/factory.h"

#include "bodyd/inference/diffusion.h"
#include "bodyd/inference/ik.h"
#include "bodyd/inference/model_file.h"

#include <fmt/format.h>
#include <fmt/ranges.h>

namespace bodyd {

namespace {
constexpr const char* kNeedsModel =
    "method 'diffusion' needs a model file (--model; the default is models/bodyd-default.safetensors)";
}  // namespace

std::vector<std::string> known_methods() { return {"diffusion", "ik"}; }

std::shared_ptr<const inference::Model> load_reconstructor_model(const std::filesystem::path& model_path) {
  if (model_path.empty()) throw ReconstructorError("", kNeedsModel);
  try {
    return inference::load_model(model_path);
  } catch (const inference::ModelFileError& e) {
    // No advice here: the caller (the daemon, a tool) adds the one hint that fits it.
    throw ReconstructorError(e.problem().under("cannot load the model"));
  }
}

std::unique_ptr<Reconstructor> make_reconstructor(std::string_view method, const std::filesystem::path& model_path,
                                                  const Skeleton* skeleton_hint,
                                                  const ReconstructorOptions& options) {
  return make_reconstructor_of(method, method == "diffusion" ? load_reconstructor_model(model_path) : nullptr,
                               skeleton_hint, options);
}

std::unique_ptr<Reconstructor> make_reconstructor_of(std::string_view method,
                                                     std::shared_ptr<const inference::Model> model,
                                                     const Skeleton* skeleton_hint,
                                                     const ReconstructorOptions& options) {
  if (method == "ik") {
    if (skeleton_hint == nullptr)
      throw ReconstructorError("", "method 'ik' needs a skeleton", "pass the skeleton of the motion data (a BVH file)");
    try {
      return std::make_unique<IkReconstructor>(*skeleton_hint);
    } catch (const UserError& e) {
      throw ReconstructorError(e.problem().under("method 'ik'"));
    }
  }
  if (method == "diffusion") {
    if (model == nullptr) throw ReconstructorError("", kNeedsModel);
    DiffusionOptions d;
    d.steps = options.diffusion_steps;
    d.guidance = options.guidance;
    if (options.weights) d.weights = *options.weights;
    d.seed = options.seed;
    d.filter = options.filter;
    d.body_filter = options.body_filter;
    if (options.contact_on) d.contact_on = *options.contact_on;
    if (options.contact_off) d.contact_off = *options.contact_off;
    if (options.foot_contact_speed_m_s) d.foot_contact_speed_m_s = *options.foot_contact_speed_m_s;
    if (options.foot_unlock_distance_m) d.foot_unlock_distance_m = *options.foot_unlock_distance_m;
    if (options.foot_release_half_life_s) d.foot_release_half_life_s = *options.foot_release_half_life_s;
    if (options.elbow_pole_bias_m) d.elbow_pole_bias_m = *options.elbow_pole_bias_m;
    if (options.leg_position_blend) d.leg_position_blend = *options.leg_position_blend;
    try {
      return std::make_unique<DiffusionReconstructor>(std::move(model), d);
    } catch (const UserError& e) {
      throw ReconstructorError(e.problem().under("method 'diffusion'"));
    }
  }
  throw ReconstructorError("", fmt::format("unknown reconstruction method '{}'", method),
                           fmt::format("use one of: {}", fmt::join(known_methods(), ", ")));
}

}  // namespace bodyd
