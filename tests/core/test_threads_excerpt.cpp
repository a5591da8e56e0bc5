// The shared thread-count bound (core/threads.h) and short quotes of user text in errors (core/excerpt.h).
#include <gtest/gtest.h>

#include <thread>

#include "core/error.h"
#include "core/excerpt.h"
#include "core/threads.h"
#include "test_util.h"

using namespace hgs;

TEST(Threads, BoundIsFourTimesTheHardwareThreads) {
  const unsigned h = std::max(1u, std::thread::hardware_concurrency());
  EXPECT_EQ(max_threads(), int(4 * h));
  EXPECT_EQ(checked_threads(1, "n"), 1);
  EXPECT_EQ(checked_threads(max_threads(), "n"), max_threads());
  for (long long bad : {0LL, -1LL, (long long)max_threads() + 1, 100000LL, 1LL << 40}) {
    const std::string e = test::error_of([&] { checked_threads(bad, "--threads"); });
    EXPECT_EQ(e, "--threads must be " + threads_range_text() + ", got " + std::to_string(bad));
  }
  EXPECT_NE(threads_range_text().find("1.." + std::to_string(max_threads())), std::string::npos);
}

TEST(Excerpt, ShortTextIsKeptLongTextIsCutOnOneLine) {
  EXPECT_EQ(excerpt("teal flower pot"), "teal flower pot");
  EXPECT_EQ(excerpt(std::string(80, 'a')), std::string(80, 'a'));
  EXPECT_EQ(excerpt(std::string(1000000, 'a')), std::string(80, 'a') + "… (1000000 characters)");
  EXPECT_EQ(excerpt("a\nb\tc\x01"), "a\\nb\\tc\\x01");
  // Never cut inside a UTF-8 sequence: 81 two-byte characters keep 80 whole ones.
  std::string e;
  for (int i = 0; i < 81; ++i) e += "é";
  std::string want;
  for (int i = 0; i < 80; ++i) want += "é";
  EXPECT_EQ(excerpt(e), want + "… (81 characters)");
  EXPECT_EQ(excerpt("abcdef", 3), "abc… (6 characters)");
}
