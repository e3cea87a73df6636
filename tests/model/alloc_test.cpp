// The forward pass and the sampler must not allocate. The test-support allocation counter
// (tests/support, bodyd/test/alloc_counter.h) replaces malloc & co. (and so operator new, which
// calls malloc) with counting wrappers around glibc's implementation, so Eigen's internal
// allocations are seen too; in a sanitizer build it counts operator new only, so these skip.
#include "bodyd/inference/mlpwin.h"
#include "bodyd/inference/sampler.h"
#include "test_util.h"

#include "bodyd/test/alloc_counter.h"

#include <gtest/gtest.h>

#include <cstdlib>

namespace bodyd::test {
namespace {

using inference::MlpWin;
using inference::MlpWinScratch;
using inference::Sampler;
using inference::SamplerOptions;

TEST(Allocation, CounterSeesAllocations) {
  if (!AllocationCounter::counts_malloc()) GTEST_SKIP() << "sanitizer build: malloc is not ours to count";
  AllocationCounter allocations;
  // Stored where the optimiser must keep them, so that no allocation is elided.
  static std::vector<float>* volatile vector;
  static void* volatile block;
  vector = new std::vector<float>(1000);
  block = std::malloc(64);
  std::free(block);
  delete vector;
  EXPECT_GE(allocations.count(), 3);  // the counter can fail
}

TEST(Allocation, ForwardAndSampleDoNotAllocate) {
  if (!AllocationCounter::counts_malloc()) GTEST_SKIP() << "sanitizer build: malloc is not ours to count";
  const auto tiny = inference::load_model(tiny_model_path());
  // Default-size shapes, so Eigen takes the same product paths as with a real model.
  const auto model = random_model(inference::MlpWinConfig{20, 191, 64, 512, 2, 64, 100}.to_model_config(), 1, *tiny);
  const auto net = std::make_shared<const MlpWin>(model);
  const std::size_t n = static_cast<std::size_t>(net->window_size());
  std::vector<float> x(2 * n, 0.3f), m(2 * n, 0.0f), out(2 * n);
  for (std::size_t i = 0; i < m.size(); i += 4) m[i] = 1.0f;
  MlpWinScratch scratch(*net, 2);
  Sampler plain(net, SamplerOptions{4, 1.0f, 0.0f}, 1);
  Sampler guided(net, SamplerOptions{4, 2.0f, 0.5f}, 1);
  const std::span<const float> x1(x.data(), n), m1(m.data(), n);
  const std::span<float> out1(out.data(), n);

  AllocationCounter allocations;
  for (int i = 0; i < 3; ++i) {
    net->forward(x1, m1, 50, out1, scratch);
    net->forward(x, m, 99, out, scratch);
    plain.sample(x1, m1, out1);
    plain.sample_from_noise(x1, m1, std::span<const float>(x.data() + n, n), out1);
    guided.sample(x1, m1, out1);
  }
  EXPECT_EQ(allocations.count(), 0);
}

TEST(Allocation, NewestFrameAndOnlineSampleDoNotAllocateWithEitherWeights) {
  if (!AllocationCounter::counts_malloc()) GTEST_SKIP() << "sanitizer build: malloc is not ours to count";
  const auto tiny = inference::load_model(tiny_model_path());
  const auto model = random_model(inference::MlpWinConfig{20, 191, 64, 512, 2, 64, 100}.to_model_config(), 1, *tiny);
  for (const inference::Weights weights : {inference::Weights::f32, inference::Weights::bf16}) {
    SCOPED_TRACE(std::string(inference::weights_name(weights)));
    const auto net = std::make_shared<const MlpWin>(model, weights);
    const std::size_t n = static_cast<std::size_t>(net->window_size()), D = 191;
    // The online mask: the past observed whole, the newest frame in part.
    std::vector<float> x(n, 0.3f), m(n, 1.0f), out(n), frame(D);
    for (std::size_t d = n - D; d < n; d += 2) m[d] = 0.0f;
    MlpWinScratch scratch(*net);
    Sampler sampler(net, SamplerOptions{2, 1.0f, 0.0f}, 1);
    AllocationCounter allocations;
    for (int i = 0; i < 3; ++i) {
      net->forward_newest(x, m, 50, frame, scratch);  // computes the past
      net->forward_newest(x, m, 20, frame, scratch);  // reuses it
      sampler.sample(x, m, out);
      x[0] += 1.0f;  // the next frame's past
    }
    EXPECT_EQ(allocations.count(), 0);
  }
}

}  // namespace
}  // namespace bodyd::test
