// Not a test by itself: writes the viewer fixture (scene + hybrid model) for the browser test
// (tests/viewer/browser_test.sh) into $HGS_VIEWER_FIXTURE_OUT; skipped when that variable is unset.
#include <gtest/gtest.h>

#include <cstdlib>

#include "fixture.h"

namespace hgs::test {
namespace {

TEST(ViewerFixtureWriter, WritesSceneAndModel) {
  const char* out = std::getenv("HGS_VIEWER_FIXTURE_OUT");
  if (!out || !*out) GTEST_SKIP() << "HGS_VIEWER_FIXTURE_OUT unset (only the browser test uses this)";
  ViewerFixture f = make_viewer_fixture(out);
  EXPECT_TRUE(std::filesystem::exists(f.model));
  EXPECT_GT(f.counts.size(), 2u);
}

}  // namespace
}  // namespace hgs::test
