// bodyd-bench-net: times the denoiser's forward pass (whatever architecture the model file names),
// a K-step DDIM sample, the sample of the online case (the past observed), and, where the
// architecture has them, its newest-frame pass and one streamed frame, on one thread.
//
//   bodyd-bench-net --model MODEL.safetensors [--steps 4] [--guidance 1] [--runs 200]
//
// A default-size random model for benchmarking (no training needed):
//   python3 training/model_net.py --random-model /tmp/random.safetensors
#include "bodyd/base/user_error.h"
#include "bodyd/inference/denoiser.h"
#include "bodyd/inference/model_file.h"
#include "bodyd/inference/sampler.h"

#include <CLI/CLI.hpp>
#include <fmt/format.h>

#include <Eigen/Core>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <vector>

namespace {

struct Stats {
  double median_us, p90_us, min_us;
};

Stats summarize(std::vector<double> us) {
  std::sort(us.begin(), us.end());
  return {us[us.size() / 2], us[(us.size() * 9) / 10], us.front()};
}

template <typename F>
Stats time_runs(int runs, F&& f) {
  for (int i = 0; i < std::max(3, runs / 10); ++i) f();  // warm caches
  std::vector<double> us;
  us.reserve(static_cast<std::size_t>(runs));
  for (int i = 0; i < runs; ++i) {
    const auto t0 = std::chrono::steady_clock::now();
    f();
    const auto t1 = std::chrono::steady_clock::now();
    us.push_back(std::chrono::duration<double, std::micro>(t1 - t0).count());
  }
  return summarize(std::move(us));
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"Times the bodyd network forward pass and a K-step DDIM sample on one thread"};
  std::string model_path;
  int steps = 4;
  float guidance = 1.0f;
  int runs = 200;
  app.add_option("--model", model_path, "model file (docs/model-file.md)")->required();
  app.add_option("--steps", steps, "DDIM steps K")->check(CLI::PositiveNumber);
  app.add_option("--guidance", guidance, "classifier-free guidance scale (1 = one pass per step)");
  app.add_option("--runs", runs, "timed runs (median reported)")->check(CLI::Range(1, 1000000));
  std::string weights_text = "bf16";
  app.add_option("--weights", weights_text,
                 "the online pass's weights, f32 or bf16 (the reconstructor's default: bf16; docs/model.md, \"Weights in bf16\")")
      ->capture_default_str()
      ->check(CLI::IsMember({"f32", "bf16"}));
  CLI11_PARSE(app, argc, argv);

  using namespace bodyd::inference;
  Eigen::setNbThreads(1);
  std::shared_ptr<const Model> model;
  try {
    model = load_model(model_path);
  } catch (const ModelFileError& e) {
    std::fprintf(stderr, "bodyd-bench-net: %s\n", e.what());
    return 1;
  }
  std::shared_ptr<const Denoiser> net;
  try {
    net = make_denoiser(*model, *parse_weights(weights_text));
  } catch (const ModelFileError& e) {
    std::fprintf(stderr, "bodyd-bench-net: %s\n", e.what());
    return 1;
  }
  const std::size_t window = static_cast<std::size_t>(net->window_size());
  const std::size_t dim = static_cast<std::size_t>(net->dim());
  const int t_mid = net->steps() / 2;

  bodyd::inference::Rng rng(1);
  std::vector<float> x(window), m(window), out(window);
  for (std::size_t i = 0; i < window; ++i) {
    x[i] = rng.normal();
    // Head and hands style mask: a few feature columns observed in every frame.
    m[i] = (i % dim) < 27 ? 1.0f : 0.0f;
  }

  fmt::print("model {}: {} {}, online weights {}\n", model_path, net->architecture(), model->config.to_string(),
             weights_name(net->weights()));
  const auto scratch = net->make_scratch(2);
  const Stats fwd = time_runs(runs, [&] { net->forward(x, m, t_mid, out, *scratch); });
  fmt::print("forward (batch 1):       median {:8.1f} us  p90 {:8.1f} us  min {:8.1f} us  ({} runs)\n", fwd.median_us,
             fwd.p90_us, fwd.min_us, runs);
  std::vector<float> x2(2 * window), m2(2 * window), out2(2 * window);
  std::copy(x.begin(), x.end(), x2.begin());
  std::copy(m.begin(), m.end(), m2.begin());
  const Stats fwd2 = time_runs(runs, [&] { net->forward(x2, m2, t_mid, out2, *scratch); });
  fmt::print("forward (batch 2):       median {:8.1f} us  p90 {:8.1f} us  min {:8.1f} us\n", fwd2.median_us, fwd2.p90_us,
             fwd2.min_us);

  try {
    Sampler sampler(net, SamplerOptions{steps, guidance, 0.0f}, 7);
    const Stats smp = time_runs(runs, [&] { sampler.sample(x, m, out); });
    fmt::print("sample (K={}, s={}):      median {:8.1f} us  p90 {:8.1f} us  min {:8.1f} us\n", steps, guidance,
               smp.median_us, smp.p90_us, smp.min_us);
    // The online reconstructor's case, what a frame costs: every frame but the newest observed,
    // trackers in the newest (an architecture with a newest-frame pass computes that frame alone),
    // from one fixed noise draw as the reconstructor's default (DiffusionOptions::fixed_noise).
    std::vector<float> online(m);
    std::fill(online.begin(), online.end() - static_cast<std::ptrdiff_t>(dim), 1.0f);
    std::vector<float> noise(window);
    Rng noise_rng(11);
    for (float& v : noise) v = noise_rng.normal();
    // Each run is a new frame: the window moves on by one frame (here: the frames rotate), so what a
    // network keeps from the last call's past (TcnMlp, Tcn) is computed again, as online.
    std::vector<float> moving(x);
    const Stats onl = time_runs(runs, [&] {
      std::rotate(moving.begin(), moving.begin() + static_cast<std::ptrdiff_t>(dim), moving.end());
      sampler.sample_from_noise(moving, online, noise, out);
    });
    fmt::print("sample online (K={}):     median {:8.1f} us  p90 {:8.1f} us  min {:8.1f} us\n", steps, onl.median_us,
               onl.p90_us, onl.min_us);
  } catch (const bodyd::UserError& e) {
    std::fprintf(stderr, "bodyd-bench-net: %s\n", e.what());
    return 1;
  }
  if (net->computes_newest_alone()) {
    std::vector<float> y(dim);
    // A new window each run, as at a sample's first step (later steps reuse what depends on the past).
    std::vector<float> moving(x);
    const Stats nw = time_runs(runs, [&] {
      std::rotate(moving.begin(), moving.begin() + static_cast<std::ptrdiff_t>(dim), moving.end());
      net->forward_newest(moving, m, t_mid, y, *scratch);
    });
    fmt::print("forward newest frame:    median {:8.1f} us  p90 {:8.1f} us  min {:8.1f} us\n", nw.median_us, nw.p90_us,
               nw.min_us);
  }
  // An architecture that streams (Denoiser::make_stream): one new frame at one step, the cost per
  // frame of a streamed step whatever the history.
  if (const auto stream = net->make_stream(t_mid)) {
    std::size_t frame = 0;
    const std::size_t frames = window / dim;
    std::vector<float> y(dim);
    const Stats str = time_runs(runs, [&] {
      const std::size_t f = frame++ % frames;
      stream->push(std::span(x).subspan(f * dim, dim), std::span(m).subspan(f * dim, dim), y);
    });
    fmt::print("stream (one frame):      median {:8.1f} us  p90 {:8.1f} us  min {:8.1f} us\n", str.median_us, str.p90_us,
               str.min_us);
  }
  return 0;
}
