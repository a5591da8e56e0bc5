// `hgs masks <subcommand>`: make, import, associate and score a scene's per-view masks. The subcommands register
// themselves in masks_registry() (masks_command.h); this file only assembles them, and lists their names in the
// description `hgs --help` shows.
#include <fmt/format.h>

#include <algorithm>

#include "cli/masks_command.h"

namespace hgs::cli {

std::vector<CommandSpec>& masks_registry() {
  static std::vector<CommandSpec> r;
  return r;
}

namespace {

CommandRegistration reg({"masks",
                         "Per-view masks: make them with SAM, import them from SAM / SAM2 / LangSplat, associate their "
                         "ids across views, score them",
                         15, [](CLI::App& sub) {
                           sub.require_subcommand(1);
                           auto& subs = masks_registry();
                           std::sort(subs.begin(), subs.end(),
                                     [](const CommandSpec& a, const CommandSpec& b) { return a.order < b.order; });
                           auto run = std::make_shared<std::function<void()>>();
                           std::string names;
                           for (auto& spec : subs) {
                             CLI::App* s = sub.add_subcommand(spec.name, spec.help);
                             auto fn = spec.setup(*s);
                             s->callback([fn, run] { *run = fn; });
                             names += (names.empty() ? "" : ", ") + spec.name;
                           }
                           sub.description(fmt::format("{} (subcommands: {})", sub.get_description(), names));
                           return [run] {
                             if (*run) (*run)();
                           };
                         }});

}  // namespace
}  // namespace hgs::cli
