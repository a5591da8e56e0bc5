// `hgs masks <subcommand>`: bring per-view masks from other tools into a scene. The subcommands register
// themselves in masks_registry() (masks_command.h); this file only assembles them.
#include <algorithm>

#include "cli/masks_command.h"

namespace hgs::cli {

std::vector<CommandSpec>& masks_registry() {
  static std::vector<CommandSpec> r;
  return r;
}

namespace {

CommandRegistration reg({"masks", "Import per-view masks from SAM / SAM2 / LangSplat into a scene's masks/ (subcommands: import, associate, score)", 15,
                         [](CLI::App& sub) {
                           sub.require_subcommand(1);
                           auto& subs = masks_registry();
                           std::sort(subs.begin(), subs.end(), [](const CommandSpec& a, const CommandSpec& b) { return a.order < b.order; });
                           auto run = std::make_shared<std::function<void()>>();
                           for (auto& spec : subs) {
                             CLI::App* s = sub.add_subcommand(spec.name, spec.help);
                             auto fn = spec.setup(*s);
                             s->callback([fn, run] { *run = fn; });
                           }
                           return [run] {
                             if (*run) (*run)();
                           };
                         }});

}  // namespace
}  // namespace hgs::cli
