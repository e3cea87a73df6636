#include "bodyd/inference/factory.h"

#include "bodyd/inference/ik.h"

#include <fmt/format.h>
#include <fmt/ranges.h>

namespace bodyd {

std::vector<std::string> known_methods() { return {"diffusion", "ik"}; }

std::unique_ptr<Reconstructor> make_reconstructor(std::string_view method, const std::filesystem::path& model_path,
                                                  const Skeleton* skeleton_hint) {
  if (method == "ik") {
    if (skeleton_hint == nullptr)
      throw ReconstructorError("method 'ik' needs a skeleton: pass the skeleton of the motion data (a BVH file)");
    try {
      return std::make_unique<IkReconstructor>(*skeleton_hint);
    } catch (const std::invalid_argument& e) {
      throw ReconstructorError(fmt::format("method 'ik': {}", e.what()));
    }
  }
  if (method == "diffusion") {
    // Replaced by the diffusion reconstructor (diffusion.h) once it is wired in.
    (void)model_path;
    throw ReconstructorError("diffusion method not available yet (use --methods ik)");
  }
  throw ReconstructorError(fmt::format("unknown reconstruction method '{}' (known: {})", method,
                                       fmt::join(known_methods(), ", ")));
}

}  // namespace bodyd
