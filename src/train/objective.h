// The training objective of one step: a weighted sum of named loss terms, L = sum_i weight_i * value_i. Every
// term's gradient is computed already scaled by its weight by whoever adds it; the objective only keeps the
// values, so the total reported (progress line, train_stats.json) is the one optimised.
#pragma once
#include <string>
#include <vector>

namespace hgs::train {

struct LossTerm {
  std::string name;  // "rgb", "app", "bro", "sem", ...
  float weight = 1;
  double value = 0;  // unweighted
  double weighted() const { return double(weight) * value; }
};

class Objective {
 public:
  void clear() { terms_.clear(); }
  // Adds a term (a weight of 0 still records its value; it adds nothing to the total).
  void add(const std::string& name, float weight, double value) { terms_.push_back({name, weight, value}); }
  double total() const {
    double t = 0;
    for (const LossTerm& l : terms_) t += l.weighted();
    return t;
  }
  const std::vector<LossTerm>& terms() const { return terms_; }

 private:
  std::vector<LossTerm> terms_;
};

}  // namespace hgs::train
