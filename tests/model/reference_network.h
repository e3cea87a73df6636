// Plain reference implementation of mlpwin-v1 (naive loops, double precision), straight from the
// specification in docs/model-file.md and the model's tensors by name. Used only by the tests.
#pragma once

#include "bodyd/inference/model_file.h"

#include <span>
#include <vector>

namespace bodyd::test {

// x, m: W * D floats, frame-major; returns x0_hat (W * D) in double.
[[nodiscard]] std::vector<double> reference_forward(const inference::Model& model, std::span<const float> x,
                                                    std::span<const float> m, int t);

}  // namespace bodyd::test
