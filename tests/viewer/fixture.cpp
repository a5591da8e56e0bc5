// The viewer fixture and the helpers of fixture.h.
#include "fixture.h"

#include <arpa/inet.h>
#include <fmt/format.h>
#include <gtest/gtest.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <cctype>
#include <vector>

#include "core/error.h"
#include "core/image.h"
#include "model/gaussian_model.h"
#include "model/ply.h"
#include "scene/scene.h"

namespace hgs::test {
namespace fs = std::filesystem;

ViewerFixture make_viewer_fixture(const fs::path& dir) {
  ViewerFixture f;
  f.scene = dir / "scene";
  f.model = dir / "model.ply";
  RunResult r = run_hgs("synth --world simple --out '" + f.scene.string() +
                        "' --views 16 --width 96 --height 72 --objects 4 --points 3000 --feature-dim 32 "
                        "--supersample 1 --quiet");
  if (r.exit_code != 0) fail("hgs synth failed: {}", r.err);
  Scene s = load_scene(f.scene);
  f.names = s.object_names;
  const int K = s.num_objects();
  GaussianModel m = init_from_points(s.points, s.point_colors, 0);
  const int N = m.n;
  std::fill(m.opacity_logit.begin(), m.opacity_logit.end(), inverse_sigmoid(0.9f));
  // Majority ground-truth object over the views where the point projects inside the image.
  std::vector<int> votes(size_t(N) * (K + 1), 0);
  for (const View& v : s.views) {
    LabelMap gt = load_label_png(f.scene / "gt" / "instances" / (v.stem + ".png"));
    for (int i = 0; i < N; ++i) {
      const Eigen::Vector3d p = v.R * s.points[i].cast<double>() + v.t;
      if (p.z() <= 1e-6) continue;
      const int x = int(v.fx * p.x() / p.z() + v.cx), y = int(v.fy * p.y() / p.z() + v.cy);
      if (x < 0 || y < 0 || x >= gt.width || y >= gt.height) continue;
      const int k = gt.at(x, y);
      if (k <= K) votes[size_t(i) * (K + 1) + k]++;
    }
  }
  const int D = int(s.text_embeddings.begin()->second.size());
  // (References taken after the last add_extra: each may reallocate m.extras.)
  m.add_extra("obj", K + 1);
  m.add_extra("obj_id", 1);
  m.add_extra("lang", D);
  ExtraGroup &q = *m.find_extra("obj"), &z = *m.find_extra("obj_id"), &lang = *m.find_extra("lang");
  for (int i = 0; i < N; ++i) {
    const int* vi = &votes[size_t(i) * (K + 1)];
    const int k = int(std::max_element(vi, vi + K + 1) - vi);
    q.data[size_t(i) * (K + 1) + k] = 1.f;
    z.data[i] = float(k);
    f.counts[k]++;
    if (k == 0) continue;
    const std::vector<float>& e = s.text_embeddings.at(s.object_names.at(k));
    std::copy(e.begin(), e.end(), lang.data.begin() + size_t(i) * D);
  }
  write_model_ply(f.model, m);
  return f;
}

void ViewerServerTest::make_fixture() {
  dir_ = new TempDir();
  fix_ = new ViewerFixture(make_viewer_fixture(dir_->path));
}

void ViewerServerTest::start_server(viewer::ServerOptions opt) {
  session_ = new query::Session(fix_->scene, fix_->model, 1, "");
  opt.port = 0;
  server_ = new viewer::Server(*session_, opt);
  port_ = server_->start();
}

void ViewerServerTest::TearDownTestSuite() {
  delete server_;
  delete session_;
  delete fix_;
  delete dir_;
  server_ = nullptr;
  session_ = nullptr;
  fix_ = nullptr;
  dir_ = nullptr;
}

std::string url_encode(const std::string& s) {
  std::string o;
  for (unsigned char c : s) {
    if (std::isalnum(c) || c == '-' || c == '_' || c == '.') o += char(c);
    else o += fmt::format("%{:02X}", c);
  }
  return o;
}

int connect_loopback(int port) {
  int fd = ::socket(AF_INET, SOCK_STREAM, 0);
  sockaddr_in a{};
  a.sin_family = AF_INET;
  a.sin_port = htons(uint16_t(port));
  a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  if (::connect(fd, reinterpret_cast<sockaddr*>(&a), sizeof a) != 0) {
    ::close(fd);
    return -1;
  }
  timeval tv{20, 0};
  ::setsockopt(fd, SOL_SOCKET, SO_RCVTIMEO, &tv, sizeof tv);
  return fd;
}

std::string raw(int port, const std::string& request) {
  const int fd = connect_loopback(port);
  if (fd < 0) return "";
  for (size_t done = 0; done < request.size();) {
    const ssize_t n = ::send(fd, request.data() + done, request.size() - done, MSG_NOSIGNAL);
    if (n <= 0) break;  // the server may close early (oversize input): read what it said
    done += size_t(n);
  }
  std::string out;
  char buf[4096];
  for (ssize_t n; (n = ::read(fd, buf, sizeof buf)) > 0;) {
    out.append(buf, size_t(n));
    const size_t h = out.find("\r\n\r\n");
    if (h == std::string::npos) continue;
    const size_t cl = out.find("Content-Length: ");
    if (cl == std::string::npos || cl > h || out.size() >= h + 4 + std::stoul(out.substr(cl + 16))) break;
  }
  ::close(fd);
  return out;
}

int status_of(const std::string& response) {
  if (response.rfind("HTTP/1.1 ", 0) != 0) return -1;
  return std::stoi(response.substr(9, 3));
}

}  // namespace hgs::test
