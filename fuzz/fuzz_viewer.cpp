// Viewer request handling: `hgs view SCENE --model FILE` -> viewer::Server's routes and handlers (paths, query
// strings, JSON bodies, static files), fed one raw HTTP request from memory through httplib's own request
// parser (httplib::Server::process_request), without a socket. A 500 answer ("internal error": an exception
// other than hgs::Error / a client error escaped a handler) counts as a finding, as does a file outside the
// static folder being served.
// Project headers (Eigen) come before httplib.h: <resolv.h> defines a `_res` macro that breaks Eigen.
#include <cstring>
#include <memory>
#include <string_view>

#include "core/error.h"
#include "core/fs.h"
#include "fuzz.h"
#include "model/gaussian_model.h"
#include "model/ply.h"
#include "query/session.h"
#include "scene/scene.h"
#include "viewer/server.h"

#include <httplib.h>

namespace {
namespace fs = std::filesystem;

// One request's bytes in, the response's bytes out.
class MemoryStream : public httplib::Stream {
 public:
  MemoryStream(const uint8_t* data, size_t size) : in_(reinterpret_cast<const char*>(data), size) {}
  bool is_readable() const override { return true; }
  bool is_writable() const override { return true; }
  ssize_t read(char* ptr, size_t size) override {
    size = std::min(size, in_.size() - pos_);
    std::memcpy(ptr, in_.data() + pos_, size);
    pos_ += size;
    return ssize_t(size);
  }
  ssize_t write(const char* ptr, size_t size) override {
    out.append(ptr, size);
    return ssize_t(size);
  }
  void get_remote_ip_and_port(std::string& ip, int& port) const override { ip = "127.0.0.1", port = 40000; }
  void get_local_ip_and_port(std::string& ip, int& port) const override { ip = "127.0.0.1", port = 7860; }
  socket_t socket() const override { return 0; }
  std::string out;

 private:
  std::string_view in_;
  size_t pos_ = 0;
};

class MemoryServer : public httplib::Server {
 public:
  void feed(httplib::Stream& s) {
    bool closed = false;
    process_request(s, true, closed, nullptr);
  }
};

// The tiny scene with a hybrid-style model (object probabilities, hard ids, language features: one object per
// Gaussian, by point index) and a static folder holding index.html, with a secret file and a symlink to it
// beside/inside it.
struct Viewer {
  fs::path dir = hgs::fuzz::scratch("viewer");
  std::unique_ptr<hgs::query::Session> session;
  MemoryServer* http = nullptr;  // owned by server
  std::unique_ptr<hgs::viewer::Server> server;

  Viewer() {
    const fs::path scene = hgs::fuzz::tiny_scene();
    const hgs::Scene s = hgs::load_scene(scene);
    hgs::GaussianModel m = hgs::init_from_points(s.points, s.point_colors, 0);
    const int K = int(s.object_names.size()), D = int(s.text_embeddings.begin()->second.size());
    m.add_extra("obj", K + 1);  // all groups first: add_extra may move the earlier ones
    m.add_extra("obj_id", 1);
    m.add_extra("lang", D);
    hgs::ExtraGroup &q = m.extras[0], &z = m.extras[1], &lang = m.extras[2];
    for (int i = 0; i < m.n; ++i) {
      const int k = i % (K + 1);
      q.data[size_t(i) * (K + 1) + k] = 1.f;
      z.data[i] = float(k);
      if (k == 0) continue;
      const std::vector<float>& e = s.text_embeddings.at(s.object_names.at(k));
      std::copy(e.begin(), e.end(), lang.data.begin() + size_t(i) * D);
    }
    hgs::write_model_ply(dir / "model.ply", m);
    hgs::atomic_write_text(dir / "www" / "index.html", "<html>hgs</html>");
    hgs::atomic_write_text(dir / "www" / "assets" / "app.js", "console.log(1)");
    hgs::atomic_write_text(dir / "secret.txt", "TOP-SECRET");
    fs::create_symlink(dir / "secret.txt", dir / "www" / "link.txt");
    session = std::make_unique<hgs::query::Session>(scene, dir / "model.ply", 1, "");
    hgs::viewer::ServerOptions opt;
    opt.static_dir = dir / "www";
    auto h = std::make_unique<MemoryServer>();
    http = h.get();
    server = std::make_unique<hgs::viewer::Server>(*session, opt, std::move(h));
  }
};

}  // namespace

HGS_FUZZ_TARGET(viewer) {
  static Viewer v;
  MemoryStream s(data, size);
  v.http->feed(s);
  if (s.out.rfind("HTTP/1.1 500", 0) == 0) __builtin_trap();  // an internal error escaped a handler
  // A file outside the static folder was served: its content in the answer, unless the request itself holds it
  // (an error message may echo the request's path; libFuzzer learns the string from this very comparison).
  const std::string_view in(reinterpret_cast<const char*>(data), size);
  if (s.out.find("TOP-SECRET") != std::string::npos && in.find("TOP-SECRET") == std::string_view::npos)
    __builtin_trap();
  return 0;
}
