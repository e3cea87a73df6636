// The shipped model, for the inference tests that run it (skipped where the file is missing).
#pragma once

#include "bodyd/inference/model_file.h"
#include "../test_paths.h"

#include <gtest/gtest.h>

#include <filesystem>
#include <memory>

namespace bodyd::test {

inline std::filesystem::path default_model_path() { return source_dir() / "models" / "bodyd-default.safetensors"; }

// A fixture holding the shipped model in model_.
class DefaultModelTest : public ::testing::Test {
 protected:
  void SetUp() override {
    if (!std::filesystem::exists(default_model_path())) GTEST_SKIP() << "no default model at " << default_model_path();
    model_ = inference::load_model(default_model_path());
  }
  std::shared_ptr<const inference::Model> model_;
};

}  // namespace bodyd::test
