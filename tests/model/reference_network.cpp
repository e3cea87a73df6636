#include "reference_network.h"

#include "bodyd/inference/mlpwin.h"

#include <cmath>
#include <string>

namespace bodyd::test {
namespace {

using Vec = std::vector<double>;

double silu(double v) { return v / (1.0 + std::exp(-v)); }

// y = W v + b with W (out x in) row-major from the model.
Vec linear(const inference::Model& model, const std::string& name, const Vec& v) {
  const auto& w = model.tensor(name + ".weight");
  const auto& b = model.tensor(name + ".bias");
  const auto out = static_cast<std::size_t>(w.shape[0]);
  const auto in = static_cast<std::size_t>(w.shape[1]);
  Vec y(out);
  for (std::size_t o = 0; o < out; ++o) {
    double acc = b.data[o];
    for (std::size_t i = 0; i < in; ++i) acc += static_cast<double>(w.data[o * in + i]) * v[i];
    y[o] = acc;
  }
  return y;
}

Vec layer_norm(const inference::Model& model, const std::string& name, const Vec& v) {
  const auto& g = model.tensor(name + ".weight");
  const auto& b = model.tensor(name + ".bias");
  double mean = 0.0;
  for (double x : v) mean += x;
  mean /= static_cast<double>(v.size());
  double var = 0.0;
  for (double x : v) var += (x - mean) * (x - mean);
  var /= static_cast<double>(v.size());
  Vec y(v.size());
  for (std::size_t i = 0; i < v.size(); ++i) y[i] = (v[i] - mean) / std::sqrt(var + 1e-5) * g.data[i] + b.data[i];
  return y;
}

Vec silu(Vec v) {
  for (double& x : v) x = silu(x);
  return v;
}

}  // namespace

std::vector<double> reference_forward(const inference::Model& model, std::span<const float> x, std::span<const float> m,
                                      int t) {
  const auto c = inference::MlpWinConfig::from(model.config);
  const auto W = static_cast<std::size_t>(c.W), D = static_cast<std::size_t>(c.D), E = static_cast<std::size_t>(c.E);
  // 1. per-frame encoder on concat(x_w, m_w)
  std::vector<Vec> e(W);
  Vec e_cat;
  for (std::size_t w = 0; w < W; ++w) {
    Vec in(2 * D);
    for (std::size_t d = 0; d < D; ++d) {
      in[d] = x[w * D + d];
      in[D + d] = m[w * D + d];
    }
    e[w] = silu(linear(model, "enc", in));
    e_cat.insert(e_cat.end(), e[w].begin(), e[w].end());
  }
  // 2-3. trunk input plus time embedding
  Vec h = linear(model, "inp", e_cat);
  const std::size_t half = static_cast<std::size_t>(c.TE) / 2;
  Vec s(2 * half);
  for (std::size_t i = 0; i < half; ++i) {
    const double f = std::exp(-std::log(10000.0) * static_cast<double>(i) / static_cast<double>(half));
    s[i] = std::sin(t * f);
    s[half + i] = std::cos(t * f);
  }
  const Vec temb = linear(model, "time2", silu(linear(model, "time1", s)));
  for (std::size_t i = 0; i < h.size(); ++i) h[i] += temb[i];
  // 4. residual blocks
  for (int b = 0; b < c.L; ++b) {
    const std::string p = "blocks." + std::to_string(b) + ".";
    const Vec r = linear(model, p + "fc2", silu(linear(model, p + "fc1", layer_norm(model, p + "norm", h))));
    for (std::size_t i = 0; i < h.size(); ++i) h[i] += r[i];
  }
  // 5. output projection, frame-major
  const Vec z = linear(model, "out", silu(layer_norm(model, "out_norm", h)));
  // 6. per-frame decoder on concat(z_w, e_w)
  std::vector<double> y(W * D);
  for (std::size_t w = 0; w < W; ++w) {
    Vec in(2 * E);
    for (std::size_t i = 0; i < E; ++i) {
      in[i] = z[w * E + i];
      in[E + i] = e[w][i];
    }
    const Vec o = linear(model, "dec2", silu(linear(model, "dec1", in)));
    for (std::size_t d = 0; d < D; ++d) y[w * D + d] = o[d];
  }
  return y;
}

}  // namespace bodyd::test
