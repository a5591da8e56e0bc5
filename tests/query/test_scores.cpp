// Object ranking (query::score_objects): by cosine with the text, not by LERF relevancy, which prefers an
// embedding unlike the canonical phrases over one like the text.
#include <gtest/gtest.h>

#include <cmath>

#include "query/query.h"

namespace hgs {

TEST(ObjectScores, RankedByCosineWithRelevancyReported) {
  const int D = 3;
  query::ObjectEmbeddings oe;
  oe.num_labels = 3;
  oe.dim = D;
  const float s = std::sqrt(0.5f);
  // Object 1 lies between the text (x) and the canonical phrase (y); object 2 is far from both but on the
  // text's side of the canonical phrase: lower cosine with the text, higher LERF relevancy.
  oe.e = {0, 0, 0, /*1*/ s, s, 0, /*2*/ 0.3f, -0.954f, 0};
  oe.weight = {0, 1, 1};
  oe.count = {0, 1, 1};
  const float text[D] = {1, 0, 0};
  const query::Canonical canon = {{0, 1, 0}};
  const std::vector<query::ObjectScore> r = query::score_objects(oe, text, canon);
  ASSERT_EQ(r.size(), 2u);
  EXPECT_EQ(r[0].object, 1);
  EXPECT_EQ(r[1].object, 2);
  EXPECT_GT(r[0].cosine, r[1].cosine);
  EXPECT_LT(r[0].relevancy, r[1].relevancy);  // the order relevancy would have given is the other one
  // Objects without Gaussians are not scored.
  oe.weight[2] = 0;
  EXPECT_EQ(query::score_objects(oe, text, canon).size(), 1u);
}

}  // namespace hgs
