// Test helper: a generated world (300 m, seed 5, two target clusters) saved under the test temp dir for
// the runner, one per process (ctest runs each test case in its own process, possibly at once), and
// removed again when the suite ends.
#pragma once

#include <unistd.h>

#include <filesystem>
#include <memory>
#include <string>
#include <system_error>

#include "airground/sim/generator.hpp"
#include "airground/sim/world.hpp"

namespace ag::sim::test {

class SavedWorld {
 public:
  explicit SavedWorld(const std::string& tag) {
    namespace fs = std::filesystem;
    dir_ = (fs::path(::testing::TempDir()) / (tag + "_world_" + std::to_string(::getpid()))).string();
    GeneratorOptions g;
    g.seed = 5;
    g.size_m = 300;
    g.targets = 2;
    auto w = generate_world(g);
    if (!w.ok()) {
      error_ = w.error().message;
      return;
    }
    world_ = std::make_unique<World>(std::move(w).value());
    if (auto s = save_world(*world_, dir_); !s.ok()) error_ = s.error().message;
  }
  ~SavedWorld() {
    std::error_code ec;
    std::filesystem::remove_all(dir_, ec);
  }
  SavedWorld(const SavedWorld&) = delete;
  SavedWorld& operator=(const SavedWorld&) = delete;

  [[nodiscard]] bool ok() const { return error_.empty() && world_ != nullptr; }
  [[nodiscard]] const std::string& error() const { return error_; }
  [[nodiscard]] const std::string& dir() const { return dir_; }
  [[nodiscard]] const World* world() const { return world_.get(); }

 private:
  std::string dir_, error_;
  std::unique_ptr<World> world_;
};

}  // namespace ag::sim::test
