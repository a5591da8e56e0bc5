// MethodStats lookups by name (train/method.h).
#include "train/method.h"

#include "core/error.h"

namespace hgs::train {

double MethodStats::value(const std::string& name) const {
  for (const auto& [n, v] : values)
    if (n == name) return v;
  fail("method statistics: no value named '{}'", name);
}

const std::vector<float>& MethodStats::array(const std::string& name) const {
  for (const auto& [n, a] : arrays)
    if (n == name) return a;
  fail("method statistics: no array named '{}'", name);
}

}  // namespace hgs::train
