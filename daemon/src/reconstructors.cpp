#include "bodyd/daemon/reconstructors.h"

#include "bodyd/inference/factory.h"
#include "bodyd/motion/bvh.h"

namespace bodyd::daemon {

ReconstructorFactory make_default_factory(const std::filesystem::path& skeleton_bvh, const ReconstructorOptions& options) {
  return [skeleton_bvh, options](const ModelChoice& choice, std::string& error) -> std::unique_ptr<Reconstructor> {
    Skeleton skeleton;
    const Skeleton* hint = nullptr;
    if (choice.method == "ik") {
      try {
        skeleton = read_bvh(skeleton_bvh).skeleton;
        hint = &skeleton;
      } catch (const std::exception& e) {
        error = std::string(e.what()) + " (the ik method takes its skeleton from this BVH file; give another with --skeleton)";
        return nullptr;
      }
    }
    try {
      return make_reconstructor(choice.method, choice.model_path, hint, options);
    } catch (const std::exception& e) {
      error = e.what();
      if (choice.method == "diffusion")
        error += " (give another model with --model, or run with --method ik; the shipped models and how to "
                 "make one: docs/models.md)";
      return nullptr;
    }
  };
}

}  // namespace bodyd::daemon
