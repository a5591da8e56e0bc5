// Report aggregation and writers (JSON via nlohmann-json, Markdown by hand), both written atomically.
#include "eval/report.h"

#include <fmt/format.h>
#include <cmath>

#include "core/error.h"
#include "core/fs.h"

namespace hgs::eval {

using nlohmann::json;

namespace {

struct Acc {
  double sum = 0;
  size_t n = 0;
  void add(double v) {
    if (!std::isnan(v)) {
      sum += v;
      ++n;
    }
  }
  double mean() const { return n ? sum / double(n) : kNaN; }
};

struct RowAcc {
  Acc iou, biou, acc, loc, sec;
  size_t count = 0;
  void add(const QueryRecord& q) {
    ++count;
    sec.add(q.seconds);
    iou.add(q.iou);
    biou.add(q.biou);
    acc.add(q.acc);
    if (q.loc >= 0) loc.add(q.loc ? 1.0 : 0.0);
  }
  MeanRow row(const std::string& key) const {
    MeanRow m;
    m.key = key;
    m.count = count;
    m.miou = iou.mean();
    m.mbiou = biou.mean();
    m.macc = acc.mean();
    m.loc_acc = loc.mean();
    m.loc_count = loc.n;
    m.seconds = sec.mean();
    return m;
  }
};

template <typename KeyFn>
std::vector<MeanRow> group(const EvalReport& r, KeyFn key) {
  std::vector<std::string> order;
  std::map<std::string, RowAcc> acc;
  for (auto& q : r.records) {
    const std::string k = key(q);
    if (!acc.count(k)) order.push_back(k);
    acc[k].add(q);
  }
  std::vector<MeanRow> rows;
  for (auto& k : order) rows.push_back(acc[k].row(k));
  return rows;
}

json num(double v) { return std::isnan(v) ? json(nullptr) : json(v); }

}  // namespace

double paper_accuracy(const MeanRow& m, const std::string& protocol) {
  return protocol.starts_with("lerf-ovs") ? m.loc_acc : m.macc;
}

namespace {

json row_json(const MeanRow& m, const char* keyname, const std::string& protocol) {
  json j = {{keyname, m.key},
            {"count", m.count},
            {"mIoU", num(m.miou)},
            {"mBIoU", num(m.mbiou)},
            {"mAcc", num(paper_accuracy(m, protocol))},
            {"pixel_acc", num(m.macc)}};
  if (m.loc_count) {
    j["loc_acc"] = num(m.loc_acc);
    j["loc_count"] = m.loc_count;
  }
  if (!std::isnan(m.seconds)) j["mean_seconds"] = m.seconds;
  return j;
}

std::string pct(double v) { return std::isnan(v) ? "-" : fmt::format("{:.2f}", 100.0 * v); }

// Markdown table cells must not contain '|' or newlines.
std::string cell(const std::string& s) {
  std::string o;
  for (char c : s) {
    if (c == '|') o += "\\|";
    else if (c == '\n' || c == '\r') o += ' ';
    else o += c;
  }
  return o;
}

}  // namespace

QueryRecord lerf_record(const std::string& frame, const std::string& query, const LerfQueryResult& r, double seconds) {
  QueryRecord q;
  q.frame = frame;
  q.query = query;
  q.iou = r.scores.iou;
  q.biou = r.scores.biou;
  q.acc = r.scores.acc;
  q.loc = r.loc.hit ? 1 : 0;
  q.seconds = seconds;
  return q;
}

void add_3dovs_image(EvalReport& report, const std::string& frame, const std::vector<std::string>& classes,
                     const OvsImageResult& r) {
  if (classes.size() != r.iou.size())
    fail("eval: {} class names for a 3D-OVS result with {} classes", classes.size(), r.iou.size());
  for (size_t c = 0; c < classes.size(); ++c) {
    if (std::isnan(r.iou[c])) continue;  // not scored (labelled-only scoring, the class is not in the frame)
    QueryRecord q;
    q.frame = frame;
    q.query = classes[c];
    q.iou = r.iou[c];
    q.biou = r.biou[c];
    report.records.push_back(q);
  }
  report.frame_accuracy[frame] = r.accuracy;
}

std::vector<MeanRow> frame_means(const EvalReport& r) {
  auto rows = group(r, [](const QueryRecord& q) { return q.frame; });
  for (auto& m : rows) {
    auto it = r.frame_accuracy.find(m.key);
    if (it != r.frame_accuracy.end()) m.macc = it->second;
  }
  // Frames that only have a frame accuracy (no records) still get a row.
  for (auto& [f, a] : r.frame_accuracy) {
    bool present = false;
    for (auto& m : rows) present |= m.key == f;
    if (!present) {
      MeanRow m;
      m.key = f;
      m.macc = a;
      rows.push_back(m);
    }
  }
  return rows;
}

std::vector<MeanRow> query_means(const EvalReport& r) {
  return group(r, [](const QueryRecord& q) { return q.query; });
}

MeanRow scene_mean(const EvalReport& r) {
  RowAcc all;
  for (auto& q : r.records) all.add(q);
  MeanRow m = all.row("scene");
  if (!r.frame_accuracy.empty()) {
    Acc a;
    for (auto& [f, v] : r.frame_accuracy) a.add(v);
    m.macc = a.mean();
  }
  return m;
}

json report_json(const EvalReport& r) {
  json j;
  j["protocol"] = r.protocol;
  j["scene"] = r.scene;
  j["mode"] = r.mode;
  j["summary"] = row_json(scene_mean(r), "key", r.protocol);
  j["frames"] = json::array();
  for (auto& m : frame_means(r)) j["frames"].push_back(row_json(m, "frame", r.protocol));
  j["queries"] = json::array();
  for (auto& m : query_means(r)) j["queries"].push_back(row_json(m, "query", r.protocol));
  j["records"] = json::array();
  for (auto& q : r.records) {
    json e = {{"frame", q.frame}, {"query", q.query}, {"iou", num(q.iou)}, {"biou", num(q.biou)}, {"acc", num(q.acc)}};
    if (q.loc >= 0) e["loc_hit"] = q.loc == 1;
    if (!std::isnan(q.seconds)) e["seconds"] = q.seconds;
    j["records"].push_back(e);
  }
  j["extra"] = r.extra;
  return j;
}

std::string report_markdown(const std::vector<EvalReport>& reports) {
  std::string md =
      "# Evaluation report\n\nMetrics in percent; mIoU / mBIoU are means over (frame, query) pairs. "
      "mAcc is the accuracy the protocol's papers report: localisation accuracy for LERF-OVS, pixel "
      "accuracy otherwise.\n\n";
  md +=
      "| protocol | scene | mode | relevancy | pairs | mAcc | mIoU | mBIoU | pixel acc | loc. acc | ms/query |\n"
      "|---|---|---|---|---:|---:|---:|---:|---:|---:|---:|\n";
  for (auto& r : reports) {
    MeanRow s = scene_mean(r);
    const std::string rel = r.extra.contains("relevancy") ? r.extra["relevancy"].get<std::string>() : "-";
    md += fmt::format("| {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} |\n", cell(r.protocol), cell(r.scene),
                      cell(r.mode), cell(rel), s.count, pct(paper_accuracy(s, r.protocol)), pct(s.miou), pct(s.mbiou),
                      pct(s.macc), pct(s.loc_acc),
                      std::isnan(s.seconds) ? std::string("-") : fmt::format("{:.1f}", 1000 * s.seconds));
  }
  auto table = [&](const std::string& title, const char* keyname, const std::vector<MeanRow>& rows,
                   const MeanRow& total) {
    md += fmt::format("\n### {}\n\n| {} | n | pixel acc | mIoU | mBIoU | loc. acc |\n|---|---:|---:|---:|---:|---:|\n",
                      title, keyname);
    for (auto& m : rows)
      md += fmt::format("| {} | {} | {} | {} | {} | {} |\n", cell(m.key), m.count, pct(m.macc), pct(m.miou),
                        pct(m.mbiou), pct(m.loc_acc));
    md += fmt::format("| **scene mean** | {} | {} | {} | {} | {} |\n", total.count, pct(total.macc), pct(total.miou),
                      pct(total.mbiou), pct(total.loc_acc));
  };
  for (auto& r : reports) {
    md += fmt::format("\n## {} — {}{}\n", cell(r.protocol), cell(r.scene),
                      r.mode.empty() ? "" : " (" + cell(r.mode) + ")");
    const MeanRow s = scene_mean(r);
    if (r.extra.contains("pixel_score") && r.extra["pixel_score"].is_string())
      md += fmt::format("\nA pixel's score: {}.\n", r.extra["pixel_score"].get<std::string>());
    if (r.extra.contains("miou_ceiling") && r.extra["miou_ceiling"].is_number())
      md += fmt::format(
          "\nNo prediction can score above {} mIoU here (a class absent from a frame's ground truth "
          "scores 0, and every pixel the ground truth leaves unlabelled takes some class).\n",
          pct(r.extra["miou_ceiling"].get<double>()));
    table("Per query", "query", query_means(r), s);
    table("Per frame", "frame", frame_means(r), s);
    md += "\n### Per (frame, query)\n\n| frame | query | acc | IoU | BIoU | loc |\n|---|---|---:|---:|---:|:---:|\n";
    for (auto& q : r.records)
      md += fmt::format("| {} | {} | {} | {} | {} | {} |\n", cell(q.frame), cell(q.query), pct(q.acc), pct(q.iou),
                        pct(q.biou),
                        q.loc < 0 ? "-"
                        : q.loc   ? "hit"
                                  : "miss");
  }
  return md;
}

void write_reports(const std::filesystem::path& json_path, const std::filesystem::path& md_path,
                   const std::vector<EvalReport>& reports) {
  json j = {{"reports", json::array()}};
  for (auto& r : reports) j["reports"].push_back(report_json(r));
  const std::string js = j.dump(2) + "\n", md = report_markdown(reports);
  atomic_write_text(json_path, js);
  try {
    atomic_write_text(md_path, md);
  } catch (...) {
    std::error_code ec;
    std::filesystem::remove(json_path, ec);  // no half-written report pair
    throw;
  }
}

}  // namespace hgs::eval
