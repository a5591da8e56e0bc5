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

// Applies --threads to OpenMP, the element-wise pool and OpenBLAS (0, the option left out: all cores).
void set_threads(int threads);

// The --threads option of every command: an integer in 1..max_threads() (core/threads.h, the bound hgs.set_threads
// shares), checked while parsing, so 0, negatives and 100000 end as one line naming --threads and the range,
// exit 2. Left out, `threads` keeps its 0: every CPU this process may use.
CLI::Option* add_threads_option(CLI::App& sub, int& threads, const std::string& what = "Worker threads");

}  // namespace hgs::cli
