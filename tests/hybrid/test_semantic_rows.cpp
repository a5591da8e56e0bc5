// SemanticPass's row-sparse step of f from the factored views that other ranks send (SemanticPass::reduce, then
// update): each view's rows are placed on the threads, only those rows change, and a row outside the model (a
// corrupt or mismatched payload) fails with a one-line error instead of writing out of bounds.
#include <gtest/gtest.h>
#include <omp.h>

#include <algorithm>
#include <cstring>
#include <string>
#include <vector>

#include "core/error.h"
#include "hybrid/semantic.h"
#include "model/gaussian_model.h"
#include "train/adam.h"

using namespace hgs;
using namespace hgs::hybrid;

namespace {

constexpr int kL = 3, kD = 20, kN = 37;

// A second rank whose gather hands over `other` after this rank's own bytes.
class TwoRanks final : public train::Reducer {
 public:
  explicit TwoRanks(std::vector<uint8_t> other) : other_(std::move(other)) {}
  int size() const override { return 2; }
  std::vector<std::vector<uint8_t>> gather(const std::vector<uint8_t>& mine) override { return {mine, other_}; }

 private:
  std::vector<uint8_t> other_;
};

// One factored view in SemanticPass's wire format: count, then jf, rows, objs [jf], G [jf, D], rows, a [rows, jf].
std::vector<uint8_t> one_view(const std::vector<int>& rows) {
  std::vector<uint8_t> b;
  auto put = [&](const void* p, size_t bytes) {
    b.resize(b.size() + bytes);
    std::memcpy(b.data() + b.size() - bytes, p, bytes);
  };
  const int32_t count = 1, jf = 1, nrows = int32_t(rows.size()), obj = 1;
  put(&count, 4);
  put(&jf, 4);
  put(&nrows, 4);
  put(&obj, 4);
  std::vector<float> G(kD);
  for (int d = 0; d < kD; ++d) G[d] = 0.01f * float(d + 1);
  put(G.data(), 4 * G.size());
  put(rows.data(), 4 * rows.size());
  std::vector<float> a(rows.size());  // the rows' weights alternate in sign: each row's step shows which it got
  for (size_t r = 0; r < rows.size(); ++r) a[r] = r % 2 ? -0.5f : 0.5f;
  put(a.data(), 4 * a.size());
  return b;
}

struct World {
  HybridData data;
  GaussianModel model;
  train::Adam optim;
  World() {
    data.num_labels = kL;
    data.dim = kD;
    HybridView v;
    v.scl = {1, 2};
    data.views.push_back(v);
    model.n = kN;
    model.add_extra(kAssociationGroup, kL, 0.4f);
    model.add_extra(kHardIdGroup, 1, 0.f);
    model.add_extra(kLanguageGroup, kD, 0.1f);
    optim.add(SemanticPass::kParam, kD, kN, 1e-2f);
  }
};

}  // namespace

TEST(SemanticRows, OtherRanksRowsUpdateThoseRowsOnly) {
  const int before = omp_get_max_threads();
  for (int threads : {1, 3}) {
    omp_set_num_threads(threads);
    World s;
    SemanticPass pass(HybridConfig{}, &s.data);
    TwoRanks other(one_view({0, 5, 17, kN - 1}));
    pass.reduce(other);
    HybridFields h = HybridFields::bind(s.model, "test");
    const std::vector<float> f0 = h.f->data;
    pass.update(kN, h, s.optim, 1.f);
    const std::vector<int> rows = {0, 5, 17, kN - 1};
    for (int i = 0; i < kN; ++i) {
      const auto r = std::find(rows.begin(), rows.end(), i);
      const bool same = std::memcmp(&h.f->data[size_t(i) * kD], &f0[size_t(i) * kD], kD * sizeof(float)) == 0;
      EXPECT_EQ(same, r == rows.end()) << "row " << i << ", " << threads << " threads";
      if (r == rows.end()) continue;
      // df = q a G with q, G > 0: descent moves f against the sign of its row's a (view row r - rows.begin()).
      const float dir = (r - rows.begin()) % 2 ? 1.f : -1.f;
      for (int d = 0; d < kD; ++d)
        EXPECT_GT(dir * (h.f->data[size_t(i) * kD + d] - f0[size_t(i) * kD + d]), 0.f) << "row " << i << " d " << d;
    }
  }
  omp_set_num_threads(before);
}

TEST(SemanticRows, RowOutsideTheModelFailsNamed) {
  for (int bad : {kN, kN + 40, -3}) {
    World s;
    SemanticPass pass(HybridConfig{}, &s.data);
    TwoRanks other(one_view({2, bad, 9}));
    pass.reduce(other);
    HybridFields h = HybridFields::bind(s.model, "test");
    const std::vector<float> f0 = h.f->data;
    try {
      pass.update(kN, h, s.optim, 1.f);
      ADD_FAILURE() << "row " << bad << " was accepted";
    } catch (const Error& e) {
      const std::string m = e.what();
      EXPECT_NE(m.find("row " + std::to_string(bad) + " is outside the " + std::to_string(kN) + " Gaussians"),
                std::string::npos)
          << m;
      EXPECT_EQ(m.find('\n'), std::string::npos) << m;
    }
    EXPECT_EQ(h.f->data, f0) << "f changed although the step failed";
  }
}
