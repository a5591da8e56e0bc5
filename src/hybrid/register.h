// Registers the hybrid method ("hybrid") in the training-method registry (train/registry.h): its factory reads
// HybridConfig from the options JSON (null = defaults), loads the views' masks and features and builds the
// HybridMethod. Call it once before train::make_trainer (the CLI does at start-up).
#pragma once

namespace hgs::hybrid {

void register_method();

}  // namespace hgs::hybrid
