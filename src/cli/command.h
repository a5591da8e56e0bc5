// Subcommand registry for the `hgs` executable. Each src/cli/cmd_<name>.cpp defines one subcommand and
// registers it with a static `CommandRegistration`; main.cpp builds the CLI11 app from the registry.
#pragma once
#include <CLI/CLI.hpp>
#include <functional>
#include <string>
#include <vector>

namespace hgs::cli {

struct CommandSpec {
  std::string name;
  std::string help;
  int order;  // position in `hgs --help`
  // Adds options to `sub` and returns the function to run after parsing.
  std::function<std::function<void()>(CLI::App& sub)> setup;
};

std::vector<CommandSpec>& registry();

struct CommandRegistration {
  CommandRegistration(CommandSpec spec) { registry().push_back(std::move(spec)); }
};

// Applies --threads (0 = all cores) to OpenMP.
void set_threads(int threads);

}  // namespace hgs::cli
