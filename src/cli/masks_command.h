// Sub-subcommands of `hgs masks` (generate, click, import, associate, score). Each lives in its own
// src/cli/cmd_masks_<name>.cpp and registers itself with a static `MasksSubcommandRegistration`, like top-level
// commands do (command.h); cmd_masks.cpp builds `hgs masks` from this registry and lists the names in its
// description. A new one is one file with one registration; nothing else changes.
#pragma once
#include "cli/command.h"

namespace hgs::cli {

std::vector<CommandSpec>& masks_registry();

struct MasksSubcommandRegistration {
  MasksSubcommandRegistration(CommandSpec spec) { masks_registry().push_back(std::move(spec)); }
};

}  // namespace hgs::cli
