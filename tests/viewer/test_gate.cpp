// viewer::request_complete, the gate's test of whether a buffered request can go to a worker (gate.h): header
// end, Content-Length and chunked bodies, and the cases where waiting cannot help.
#include "viewer/gate.h"

#include <gtest/gtest.h>

#include <string>

namespace hgs::test {
namespace {
using viewer::request_complete;

TEST(GateRequestComplete, HeaderBodyAndChunkedFraming) {
  const size_t max = 1000;
  EXPECT_FALSE(request_complete("GET / HTTP/1.1\r\nHost: x\r\n", max));
  EXPECT_TRUE(request_complete("GET / HTTP/1.1\r\nHost: x\r\n\r\n", max));
  const std::string post = "POST /api/query HTTP/1.1\r\ncontent-LENGTH:  5 \r\n\r\n";
  EXPECT_FALSE(request_complete(post, max));
  EXPECT_FALSE(request_complete(post + "abcd", max));
  EXPECT_TRUE(request_complete(post + "abcde", max));
  const std::string chunked = "POST / HTTP/1.1\r\nTransfer-Encoding: chunked\r\n\r\n";
  EXPECT_FALSE(request_complete(chunked + "3\r\nabc\r\n", max));
  EXPECT_FALSE(request_complete(chunked + "3\r\nabc\r\n0\r\n", max));
  EXPECT_TRUE(request_complete(chunked + "3\r\nabc\r\n0\r\n\r\n", max));
  EXPECT_TRUE(request_complete(chunked + "0\r\n\r\n", max));
}

TEST(GateRequestComplete, HandsOverWhatWaitingCannotFix) {
  const size_t max = 1000;
  // The worker answers 100-continue, refuses an announced body over the limit (413) and a malformed length.
  EXPECT_TRUE(request_complete("POST / HTTP/1.1\r\nExpect: 100-continue\r\nContent-Length: 50\r\n\r\n", max));
  EXPECT_TRUE(request_complete("POST / HTTP/1.1\r\nContent-Length: 99999999999999999999\r\n\r\n", max));
  EXPECT_TRUE(request_complete("POST / HTTP/1.1\r\nContent-Length: 12x\r\n\r\n", max));
  // A header that never ends is handed over at the byte limit (the worker answers 431 / 400).
  EXPECT_FALSE(request_complete("GET / HTTP/1.1\r\nX: " + std::string(900, 'a'), max));
  EXPECT_TRUE(request_complete("GET / HTTP/1.1\r\nX: " + std::string(1000, 'a'), max));
  // A header name that only ends like one is not it.
  EXPECT_TRUE(request_complete("GET / HTTP/1.1\r\nX-Content-Length: 5\r\n\r\n", max));
}

}  // namespace
}  // namespace hgs::test
