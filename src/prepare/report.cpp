// The one-screen text of `hgs prepare`'s report (the same facts as SCENE/prepare.json).
#include <fmt/format.h>

#include "core/progress.h"
#include "prepare/prepare.h"

namespace hgs::prepare {

namespace {

std::string list_some(const nlohmann::json& names, size_t most = 6) {
  std::string s;
  for (size_t i = 0; i < names.size() && i < most; ++i) s += (i ? ", " : "") + names[i].get<std::string>();
  if (names.size() > most) s += fmt::format(", ... ({} in all)", names.size());
  return s;
}

}  // namespace

std::string PrepareReport::text() const {
  const nlohmann::json& j = json;
  std::string t = fmt::format("prepared {}\n", j.value("scene", ""));
  if (const auto& in = j.at("input"); !in.empty()) {
    t += fmt::format("  input      {} {} from {}", in.value("images", 0),
                     in.value("kind", "") == "video" ? "frames" : "images", in.value("path", ""));
    if (in.value("rotated", 0)) t += fmt::format(", {} rotated upright (EXIF)", in.value("rotated", 0));
    if (in.value("resized", 0)) t += fmt::format(", {} downscaled", in.value("resized", 0));
    t += "\n";
    if (!in.value("not_images", nlohmann::json::array()).empty())
      t += fmt::format("             skipped (not images): {}\n", list_some(in["not_images"]));
    if (!in.value("broken_links", nlohmann::json::array()).empty())
      t += fmt::format("             skipped (links to nothing): {}\n", list_some(in["broken_links"]));
    if (const auto renamed = in.value("renamed", nlohmann::json::array()); !renamed.empty()) {
      nlohmann::json pairs = nlohmann::json::array();
      for (const auto& r : renamed)
        pairs.push_back(r[0].dump(-1, ' ', false, nlohmann::json::error_handler_t::replace) + " -> " +
                        r[1].get<std::string>());  // escaped
      t += fmt::format("             renamed (names COLMAP cannot carry): {}\n", list_some(pairs, 3));
    }
    if (!in.value("bad", nlohmann::json::array()).empty())
      t += fmt::format("             skipped (unreadable): {}\n", list_some(in["bad"], 3));
    if (!in.value("blurred", nlohmann::json::array()).empty())
      t += fmt::format("             dropped as blurred: {}\n", list_some(in["blurred"]));
  }
  if (const auto& p = j.at("poses"); !p.empty()) {
    t += fmt::format(
        "  poses      {} of {} registered ({} matcher), {} camera{}, {} points, reprojection error {:.2f} px, track "
        "length {:.1f}\n",
        p.value("registered", 0), p.value("images", 0), p.value("matcher", ""), p.value("cameras", 0),
        p.value("cameras", 0) == 1 ? "" : "s", p.value("points", 0), p.value("mean_reprojection_error_px", 0.0),
        p.value("mean_track_length", 0.0));
    if (!p.value("retried", nlohmann::json::array()).empty())
      t += fmt::format("             retried (fewer than half registered): {}; kept: {} settings\n",
                       list_some(p["retried"]), p.value("settings", ""));
    if (!p.value("dropped", nlohmann::json::array()).empty())
      t += fmt::format("             not registered: {}\n", list_some(p["dropped"]));
  }
  if (const auto& m = j.at("masks"); m.contains("objects")) {
    const auto& mv = m.at("masks_per_view");
    t += fmt::format("  masks      {:.1f} SAM masks per view ({}-{}), {} objects after association{}\n",
                     mv.value("mean", 0.0), mv.value("min", 0), mv.value("max", 0), m.value("objects", 0),
                     m.value("depth_iters", 0) ? fmt::format(" (depth from {} RGB steps)", m.value("depth_iters", 0))
                                               : " (COLMAP points only)");
  }
  if (const auto& l = j.at("language"); l.contains("dim"))
    t += fmt::format("  language   {} feature maps (D = {}, grid {}x{}), {} phrases embedded\n", l.value("views", 0),
                     l.value("dim", 0), l["grid"][0].get<int>(), l["grid"][1].get<int>(),
                     l.value("phrases", nlohmann::json::array()).size());
  t += "  seconds   ";
  for (const StageRun& r : stages)
    t += fmt::format(" {} {}{}", r.name, format_duration(r.seconds), r.reused ? " (kept)" : "");
  t += fmt::format("\n  this run   {}\n", format_duration(j.value("total_seconds", 0.0)));
  return t;
}

}  // namespace hgs::prepare
