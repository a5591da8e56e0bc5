// The viewer tests' fixture: a tiny synthetic scene plus a hand-built hybrid model whose queries have known
// answers (every Gaussian, one per SfM point, gets the ground-truth object seen at its projection in most views as
// one-hot q and hard id, and that object's class-name text embedding as its language feature, so "red mug" picks
// the red mug); a test suite base that serves it in-process with `hgs view`'s server on a free loopback port; and
// raw-socket helpers for requests an HTTP client would normalise.
#pragma once
#include <gtest/gtest.h>

#include <filesystem>
#include <map>
#include <string>

#include "query/session.h"
#include "test_util.h"
#include "viewer/server.h"

namespace hgs::test {

struct ViewerFixture {
  std::filesystem::path scene, model;  // scene folder, model PLY
  std::map<int, std::string> names;    // object id -> name (masks/objects.json)
  std::map<int, int> counts;           // object id -> Gaussians with that hard id
};

// Writes the scene (via `hgs synth`) and the model into `dir`.
ViewerFixture make_viewer_fixture(const std::filesystem::path& dir);

// A suite whose tests share one server on the viewer fixture. SetUpTestSuite calls make_fixture(), writes what
// the suite needs into dir_, then start_server(); TearDownTestSuite stops and deletes everything.
class ViewerServerTest : public ::testing::Test {
 protected:
  // Writes the fixture into a fresh temporary folder: dir_, fix_.
  static void make_fixture();
  // Opens a session on the fixture and serves it with opt on a free loopback port: session_, server_, port_.
  static void start_server(viewer::ServerOptions opt);
  static void TearDownTestSuite();

  static inline TempDir* dir_ = nullptr;
  static inline ViewerFixture* fix_ = nullptr;
  static inline query::Session* session_ = nullptr;
  static inline viewer::Server* server_ = nullptr;
  static inline int port_ = 0;
};

// s with every byte but [A-Za-z0-9-_.] percent-encoded.
std::string url_encode(const std::string& s);

// A TCP connection to 127.0.0.1:port with a 20 s receive timeout; -1 when it fails.
int connect_loopback(int port);

// Sends raw request bytes, returns what the server answered until it closed or one response arrived.
std::string raw(int port, const std::string& request);

// The status code of a raw HTTP/1.1 response; -1 when it is not one.
int status_of(const std::string& response);

}  // namespace hgs::test
