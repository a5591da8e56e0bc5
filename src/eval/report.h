// Aggregation of per-(frame, query) evaluation records into per-frame, per-query and scene means, and the
// report writers (report.json, report.md). Means skip NaN entries (metrics that do not apply to a record).
//
// Scene means: mIoU and mBIoU are means over the (frame, query) records (for LERF-OVS that is the protocol's
// mean over pairs; for 3D-OVS every image has all C classes, so it equals the mean over images of the image
// mIoU). mAcc is the mean over frames of the frame accuracy when frame accuracies are given (3D-OVS: the
// multi-class pixel accuracy of the image), else the mean of the records' pixel accuracies. Localisation
// accuracy is hits / records that have a localisation result.
//
// Names in report.json: "mAcc" is the accuracy a paper of the protocol reports: for LERF-OVS the localisation
// accuracy (LERF, LangSplat), for 3D-OVS and instances the pixel accuracy. "pixel_acc" is always the pixel
// accuracy and "loc_acc" the localisation accuracy where there is one.
#pragma once
#include <filesystem>
#include <limits>
#include <map>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "eval/protocols.h"

namespace hgs::eval {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

struct QueryRecord {
  std::string frame;  // view / image name
  std::string query;  // category, class or text
  double iou = kNaN, biou = kNaN, acc = kNaN;
  int loc = -1;           // localisation: -1 not evaluated, 0 miss, 1 hit
  double seconds = kNaN;  // optional timing of the query
};

struct MeanRow {
  std::string key;   // frame or query name; "scene" for the scene mean
  size_t count = 0;  // records
  double miou = kNaN, mbiou = kNaN, macc = kNaN;
  double loc_acc = kNaN;
  size_t loc_count = 0;
  double seconds = kNaN;  // mean of the records' timings (NaN when none has one)
};

struct EvalReport {
  std::string protocol;  // "lerf-ovs", "3d-ovs", "instances", ...
  std::string scene;
  std::string mode;  // "object", "pixel" or "pixel-paper-map" (query/evaluate.h)
  std::vector<QueryRecord> records;
  std::map<std::string, double> frame_accuracy;     // optional per-frame accuracy overriding the record mean
  nlohmann::json extra = nlohmann::json::object();  // free-form: options, timings, paths
};

// The "mAcc" of a protocol's papers: localisation accuracy for "lerf-ovs" (and -scaled), pixel accuracy otherwise.
double paper_accuracy(const MeanRow& m, const std::string& protocol);

// Record of one LERF-OVS (frame, query) evaluation (iou, biou, acc, localisation).
QueryRecord lerf_record(const std::string& frame, const std::string& query, const LerfQueryResult& r,
                        double seconds = kNaN);
// Records of one 3D-OVS image: one per class (iou, biou; acc NaN) plus the image accuracy in frame_accuracy.
void add_3dovs_image(EvalReport& report, const std::string& frame, const std::vector<std::string>& classes,
                     const OvsImageResult& r);

// Means per frame (in first-appearance order), per query (first-appearance order) and for the scene.
std::vector<MeanRow> frame_means(const EvalReport& r);
std::vector<MeanRow> query_means(const EvalReport& r);
MeanRow scene_mean(const EvalReport& r);

// JSON of one report: {"protocol", "scene", "mode", "summary", "frames", "queries", "records", "extra"};
// NaN becomes null. Metrics are fractions in [0, 1].
nlohmann::json report_json(const EvalReport& r);
// Markdown of one or more reports: a summary table (one row per report) then per-query, per-frame and
// per-record tables for each. Metrics are printed in percent with two decimals, "-" where not applicable.
std::string report_markdown(const std::vector<EvalReport>& reports);
// Writes json_path ({"reports": [report_json, ...]}) and md_path (the Markdown), each atomically; if the
// second write fails the first file is removed again.
void write_reports(const std::filesystem::path& json_path, const std::filesystem::path& md_path,
                   const std::vector<EvalReport>& reports);

}  // namespace hgs::eval
