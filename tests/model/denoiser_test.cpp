// The architecture seam (denoiser.h): the table, the factory, and that a denoiser made from a
// model file's "architecture" field computes what that architecture's network computes.
#include "bodyd/inference/denoiser.h"
#include "bodyd/inference/mlpwin.h"
#include "test_util.h"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <string>

namespace bodyd::test {
namespace {

TEST(Denoiser, TableListsMlpWinAndNothingUnknown) {
  ASSERT_FALSE(inference::architectures().empty());
  const inference::Architecture* mlp = inference::find_architecture("mlpwin-v1");
  ASSERT_NE(mlp, nullptr);
  EXPECT_EQ(mlp->name, inference::kArchitectureMlpWin);
  EXPECT_EQ(inference::find_architecture("transformer-v9"), nullptr);
  EXPECT_EQ(inference::find_architecture(""), nullptr);
  EXPECT_NE(inference::architecture_names().find("mlpwin-v1"), std::string::npos);
  // The names in the table are unique (a second row with the same name would never be reached).
  const auto all = inference::architectures();
  for (std::size_t i = 0; i < all.size(); ++i)
    for (std::size_t j = i + 1; j < all.size(); ++j) EXPECT_NE(all[i].name, all[j].name);
}

TEST(Denoiser, FactoryBuildsTheFilesArchitectureAndMatchesPyTorch) {
  const auto model = inference::load_model(tiny_model_path());
  const auto io = inference::read_tensor_file(tiny_io_path());
  const auto cases = nlohmann::json::parse(io.metadata.at("cases"));
  const std::shared_ptr<const inference::Denoiser> denoiser = inference::make_denoiser(*model);
  ASSERT_NE(denoiser, nullptr);
  EXPECT_EQ(denoiser->architecture(), "mlpwin-v1");
  EXPECT_EQ(denoiser->frames(), model->config.frames());
  EXPECT_EQ(denoiser->dim(), model->config.dim());
  EXPECT_EQ(denoiser->steps(), model->config.steps());
  EXPECT_EQ(denoiser->frames(), 4);
  EXPECT_EQ(denoiser->steps(), 10);
  EXPECT_NE(dynamic_cast<const inference::MlpWin*>(denoiser.get()), nullptr);
  auto scratch = denoiser->make_scratch(1);
  ASSERT_NE(scratch, nullptr);
  EXPECT_EQ(scratch->max_batch(), 1);
  // Through the interface, the outputs are PyTorch's (same tolerance as MlpWin's parity test).
  for (std::size_t i = 0; i < cases["forward"].size(); ++i) {
    const std::string p = "forward." + std::to_string(i) + ".";
    const auto& expected = io.tensors.at(p + "out").data;
    std::vector<float> out(expected.size());
    denoiser->forward(io.tensors.at(p + "x").data, io.tensors.at(p + "m").data, cases["forward"][i]["t"], out, *scratch);
    EXPECT_LE(relative_error(out, expected), 1e-4) << "case " << i;
  }
}

TEST(Denoiser, UnknownArchitectureIsRefusedByName) {
  // parse_model refuses such a file (model_file_test); the factory refuses a Model that says so too.
  inference::Model model = *inference::load_model(tiny_model_path());
  model.metadata["architecture"] = "transformer-v9";
  try {
    (void)inference::make_denoiser(model);
    FAIL() << "expected ModelFileError";
  } catch (const inference::ModelFileError& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find("transformer-v9"), std::string::npos) << what;
    EXPECT_NE(what.find("mlpwin-v1"), std::string::npos) << what;  // says what this build runs
    EXPECT_NE(what.find("tiny_model.safetensors"), std::string::npos) << what;
  }
}

}  // namespace
}  // namespace bodyd::test
