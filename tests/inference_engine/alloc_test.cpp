// The forward pass and the sampler must not allocate. This binary replaces malloc & co. (and so
// operator new, which calls malloc) with counting wrappers around glibc's implementation, so Eigen's
// internal allocations are seen too. Built without sanitizers only (they replace malloc themselves).
#include "bodyd/inference/network.h"
#include "bodyd/inference/sampler.h"
#include "test_util.h"

#include <gtest/gtest.h>

#include <atomic>
#include <cstdlib>
#include <new>

#if defined(__SANITIZE_ADDRESS__)
#define BODYD_COUNT_MALLOC 0
#elif defined(__has_feature)
#if __has_feature(address_sanitizer)
#define BODYD_COUNT_MALLOC 0
#endif
#endif
#ifndef BODYD_COUNT_MALLOC
#define BODYD_COUNT_MALLOC 1
#endif

namespace {
std::atomic<long> g_allocations{0};
}

#if BODYD_COUNT_MALLOC
extern "C" {
void* __libc_malloc(std::size_t);
void* __libc_calloc(std::size_t, std::size_t);
void* __libc_realloc(void*, std::size_t);
void* __libc_memalign(std::size_t, std::size_t);

void* malloc(std::size_t n) {
  g_allocations.fetch_add(1, std::memory_order_relaxed);
  return __libc_malloc(n);
}
void* calloc(std::size_t n, std::size_t size) {
  g_allocations.fetch_add(1, std::memory_order_relaxed);
  return __libc_calloc(n, size);
}
void* realloc(void* p, std::size_t n) {
  g_allocations.fetch_add(1, std::memory_order_relaxed);
  return __libc_realloc(p, n);
}
void* memalign(std::size_t align, std::size_t n) {
  g_allocations.fetch_add(1, std::memory_order_relaxed);
  return __libc_memalign(align, n);
}
void* aligned_alloc(std::size_t align, std::size_t n) {
  g_allocations.fetch_add(1, std::memory_order_relaxed);
  return __libc_memalign(align, n);
}
int posix_memalign(void** out, std::size_t align, std::size_t n) {
  g_allocations.fetch_add(1, std::memory_order_relaxed);
  *out = __libc_memalign(align, n);
  return *out ? 0 : ENOMEM;
}
}
#endif

namespace bodyd::test {
namespace {

using inference::Network;
using inference::NetworkScratch;
using inference::Sampler;
using inference::SamplerOptions;

TEST(Allocation, CounterSeesAllocations) {
  if (!BODYD_COUNT_MALLOC) GTEST_SKIP() << "sanitizer build: malloc is not ours to count";
  const long before = g_allocations.load();
  auto* p = new std::vector<float>(1000);
  void* q = std::malloc(64);
  std::free(q);
  delete p;
  EXPECT_GE(g_allocations.load() - before, 3);  // the counter can fail
}

TEST(Allocation, ForwardAndSampleDoNotAllocate) {
  if (!BODYD_COUNT_MALLOC) GTEST_SKIP() << "sanitizer build: malloc is not ours to count";
  const auto tiny = inference::load_model(tiny_model_path());
  // Default-size shapes, so Eigen takes the same product paths as with a real model.
  const auto model = random_model(inference::MlpWinConfig{20, 191, 64, 512, 2, 64, 100}.to_model_config(), 1, *tiny);
  const auto net = std::make_shared<const Network>(model);
  const std::size_t n = static_cast<std::size_t>(net->window_size());
  std::vector<float> x(2 * n, 0.3f), m(2 * n, 0.0f), out(2 * n);
  for (std::size_t i = 0; i < m.size(); i += 4) m[i] = 1.0f;
  NetworkScratch scratch(*net, 2);
  Sampler plain(net, SamplerOptions{4, 1.0f, 0.0f}, 1);
  Sampler guided(net, SamplerOptions{4, 2.0f, 0.5f}, 1);
  const std::span<const float> x1(x.data(), n), m1(m.data(), n);
  const std::span<float> out1(out.data(), n);

  const long before = g_allocations.load();
  for (int i = 0; i < 3; ++i) {
    net->forward(x1, m1, 50, out1, scratch);
    net->forward(x, m, 99, out, scratch);
    plain.sample(x1, m1, out1);
    plain.sample_from_noise(x1, m1, std::span<const float>(x.data() + n, n), out1);
    guided.sample(x1, m1, out1);
  }
  EXPECT_EQ(g_allocations.load() - before, 0);
}

}  // namespace
}  // namespace bodyd::test
