// The mapping stages' records when a sparse capture is retried (poses.h: retry_mapping, retry_features): one
// mapper run summarised as the stage records it, the better of two results with the retries listed, and the
// one-line refusal that advises only what was not tried.
#pragma once
#include <filesystem>
#include <string>
#include <vector>

#include "prepare/poses.h"
#include "prepare/stage_info.h"

namespace hgs::prepare {

// Runs the mapper on WORK/database.db into WORK/<sparse> and summarises its largest model against `names`
// (registered 0 and no model_path when it made none), labelled with `settings`.
MappingInfo map_and_summarize(const std::filesystem::path& colmap, const std::filesystem::path& input_dir,
                              const std::filesystem::path& work, const std::vector<std::string>& names,
                              const PoseOptions& opt, const std::string& sparse, const std::filesystem::path& scene,
                              const std::string& settings);

// At least half the images in a model: no retry needed, and no refusal.
bool registered_enough(const MappingInfo& m);

// The result with more registered images (`kept` on a tie), with `retry` added to the list of retries.
MappingInfo keep_better(const MappingInfo& kept, const MappingInfo& retry);

// Fails when no model was made, or (unless allow_partial) fewer than half the images registered, naming what was
// tried and advising only what was not (another matcher when it was not exhaustive; more overlapping photos).
void check_registration(const MappingInfo& m, bool allow_partial);

}  // namespace hgs::prepare
