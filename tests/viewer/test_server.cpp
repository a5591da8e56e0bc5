// HTTP API of `hgs view` (src/viewer/server.h), served in-process on a free loopback port over a tiny
// synthetic scene with a hand-built hybrid model (fixture.h): queries, exports, 2D panels, bad requests and
// path-traversal attempts against the static folder.
// Project headers (Eigen) come before httplib.h: <resolv.h> defines a `_res` macro that breaks Eigen.
#include "core/error.h"
#include "core/fs.h"
#include "core/image.h"
#include "eval/visualize.h"
#include "fixture.h"
#include "model/ply.h"
#include "query/session.h"
#include "test_util.h"
#include "viewer/server.h"

#include <gtest/gtest.h>
#include <httplib.h>

#include <nlohmann/json.hpp>

namespace hgs::test {
namespace {
namespace fs = std::filesystem;
using nlohmann::json;

class ViewerApi : public ViewerServerTest {
 protected:
  static void SetUpTestSuite() {
    make_fixture();
    // Static folder with one page, and a secret file beside it that must never be served.
    fs::create_directories(dir_->path / "www" / "assets");
    atomic_write_text(dir_->path / "www" / "index.html", "<html>hgs test page</html>");
    atomic_write_text(dir_->path / "www" / "assets" / "app.js", "console.log(1)");
    atomic_write_text(dir_->path / "secret.txt", "TOP-SECRET");
    fs::create_symlink(dir_->path / "secret.txt", dir_->path / "www" / "link.txt");
    viewer::ServerOptions opt;
    opt.static_dir = dir_->path / "www";
    opt.max_body = 4096;
    start_server(opt);
  }
  static httplib::Client client() {
    httplib::Client c("127.0.0.1", port_);
    c.set_read_timeout(60, 0);
    return c;
  }
  static json get_json(const std::string& path, int expect = 200) {
    auto r = client().Get(path.c_str());
    EXPECT_TRUE(r) << path;
    if (!r) return {};
    EXPECT_EQ(r->status, expect) << path << ": " << r->body;
    EXPECT_EQ(r->get_header_value("Content-Type"), "application/json") << path;
    return json::parse(r->body);
  }
  static Image get_png(const std::string& path) {
    auto r = client().Get(path.c_str());
    EXPECT_TRUE(r && r->status == 200) << path << (r ? ": " + r->body : "");
    if (!r || r->status != 200) return {};
    EXPECT_EQ(r->get_header_value("Content-Type"), "image/png");
    const fs::path f = dir_->path / "tmp.png";
    atomic_write_bytes(f, r->body.data(), r->body.size());
    return load_image(f, 3);
  }
  static GaussianModel get_ply(const std::string& path, httplib::Headers* headers = nullptr) {
    auto r = client().Get(path.c_str());
    EXPECT_TRUE(r && r->status == 200) << path << (r ? ": " + r->body : "");
    if (!r || r->status != 200) return {};
    if (headers) *headers = r->headers;
    const fs::path f = dir_->path / "tmp.ply";
    atomic_write_bytes(f, r->body.data(), r->body.size());
    return read_model_ply(f);
  }
};

TEST_F(ViewerApi, DefaultsBindLoopback) {
  viewer::ServerOptions o;
  EXPECT_EQ(o.host, "127.0.0.1");
  EXPECT_EQ(server_->address(), "http://127.0.0.1:" + std::to_string(port_) + "/");
  EXPECT_TRUE(server_->has_front_end());
}

TEST_F(ViewerApi, PortInUseFailsClearly) {
  viewer::ServerOptions o;
  o.port = port_;
  viewer::Server second(*session_, o);
  try {
    second.start();
    FAIL() << "a second server bound the port in use";
  } catch (const hgs::Error& e) {
    EXPECT_NE(std::string(e.what()).find(std::to_string(port_)), std::string::npos) << e.what();
  }
  EXPECT_EQ(get_json("/api/objects")["objects"].size(), get_json("/api/scene")["objects"].size());
}

TEST_F(ViewerApi, SceneInfoHasCamerasAndObjects) {
  json s = get_json("/api/scene");
  const Scene& sc = session_->scene();
  ASSERT_EQ(s["views"].size(), sc.views.size());
  for (size_t i = 0; i < sc.views.size(); ++i) {
    const View& v = sc.views[i];
    const json& j = s["views"][i];
    EXPECT_EQ(j["name"], v.name);
    EXPECT_EQ(j["width"], v.width);
    EXPECT_DOUBLE_EQ(j["fx"].get<double>(), v.fx);
    EXPECT_DOUBLE_EQ(j["cy"].get<double>(), v.cy);
    for (int r = 0; r < 3; ++r) {
      EXPECT_DOUBLE_EQ(j["t"][r].get<double>(), v.t[r]);
      EXPECT_NEAR(j["center"][r].get<double>(), v.camera_center()[r], 1e-9);
      for (int k = 0; k < 3; ++k) EXPECT_DOUBLE_EQ(j["R"][r * 3 + k].get<double>(), v.R(r, k));
    }
  }
  EXPECT_EQ(s["gaussians"], session_->model().n);
  // Objects: exactly the foreground ids that own Gaussians, with their masks/objects.json names.
  std::vector<int> expect_ids;
  for (auto& [k, c] : fix_->counts)
    if (k > 0 && c > 0) expect_ids.push_back(k);
  ASSERT_EQ(s["objects"].size(), expect_ids.size());
  for (size_t i = 0; i < expect_ids.size(); ++i) {
    EXPECT_EQ(s["objects"][i]["id"], expect_ids[i]);
    EXPECT_EQ(s["objects"][i]["name"], fix_->names.at(expect_ids[i]));
    EXPECT_EQ(s["objects"][i]["gaussians"], fix_->counts.at(expect_ids[i]));
  }
  EXPECT_EQ(get_json("/api/objects")["objects"], s["objects"]);
  EXPECT_GT(expect_ids.size(), 2u);
}

TEST_F(ViewerApi, QueryPicksTheNamedObject) {
  for (auto& [k, c] : fix_->counts) {
    if (k == 0 || c == 0) continue;
    const std::string name = fix_->names.at(k);
    json a = get_json("/api/query?text=" + url_encode(name));
    ASSERT_FALSE(a["chosen"].empty());
    EXPECT_EQ(a["chosen"][0]["id"], k) << name;
    EXPECT_EQ(a["chosen"][0]["name"], name);
    EXPECT_EQ(a["text"], name);
    ASSERT_GE(a["results"].size(), 2u);
    for (size_t i = 1; i < a["results"].size(); ++i)
      EXPECT_GE(a["results"][i - 1]["relevancy"].get<double>(), a["results"][i]["relevancy"].get<double>());
    // POST gives the same answer.
    auto r = client().Post("/api/query", json{{"text", name}}.dump(), "application/json");
    ASSERT_TRUE(r);
    ASSERT_EQ(r->status, 200) << r->body;
    EXPECT_EQ(json::parse(r->body)["results"], a["results"]);
  }
  // min_relevancy 0.0001 chooses more than the best object when others score above it.
  auto r = client().Post("/api/query", json{{"text", "red mug"}, {"min_relevancy", 0.0001}}.dump(), "application/json");
  ASSERT_TRUE(r && r->status == 200);
  json a = json::parse(r->body);
  size_t above = 0;
  for (auto& x : a["results"]) above += x["relevancy"].get<double>() >= 0.0001;
  EXPECT_EQ(a["chosen"].size(), std::max<size_t>(1, above));
}

TEST_F(ViewerApi, ExportObjectAndSceneWithout) {
  const int N = session_->model().n;
  for (auto& [k, c] : fix_->counts) {
    if (k == 0 || c == 0) continue;
    httplib::Headers h;
    GaussianModel obj = get_ply("/api/export.ply?objects=" + std::to_string(k), &h);
    EXPECT_EQ(obj.n, c);
    ASSERT_NE(obj.find_extra("obj_id"), nullptr);  // downloads keep the hybrid groups
    ASSERT_NE(obj.find_extra("lang"), nullptr);
    for (float z : obj.find_extra("obj_id")->data) EXPECT_EQ(int(z), k);
    auto it = h.find("Content-Disposition");
    ASSERT_NE(it, h.end());
    EXPECT_EQ(it->second, "attachment; filename=\"object-" + std::to_string(k) + ".ply\"");
    GaussianModel rest = get_ply("/api/export.ply?remove=1&objects=" + std::to_string(k));
    EXPECT_EQ(rest.n, N - c);
    for (float z : rest.find_extra("obj_id")->data) EXPECT_NE(int(z), k);
  }
  GaussianModel two = get_ply("/api/export.ply?objects=1,2");
  EXPECT_EQ(two.n, fix_->counts[1] + fix_->counts[2]);
}

TEST_F(ViewerApi, DisplayModelTintIsolateRemove) {
  const GaussianModel& m = session_->model();
  GaussianModel all = get_ply("/api/model.ply");
  EXPECT_EQ(all.n, m.n);
  EXPECT_TRUE(all.extras.empty());  // the browser copy has only the standard 3DGS properties
  EXPECT_EQ(all.mean, m.mean);
  const int k = 4;
  GaussianModel tint = get_ply("/api/model.ply?objects=4&tint=1");
  ASSERT_EQ(tint.n, m.n);
  const auto& z = m.find_extra("obj_id")->data;
  const int S = m.sh_stride();
  int tinted = 0;
  for (int i = 0; i < m.n; ++i) {
    const float r0 = sh_to_rgb(m.sh[size_t(i) * S * 3]), b0 = sh_to_rgb(m.sh[size_t(i) * S * 3 + 2]);
    const float r1 = sh_to_rgb(tint.sh[size_t(i) * S * 3]), b1 = sh_to_rgb(tint.sh[size_t(i) * S * 3 + 2]);
    if (int(z[i]) == k) {
      EXPECT_NEAR(r1, 0.4f * r0 + 0.6f * 1.f, 1e-4f);
      EXPECT_NEAR(b1, 0.4f * b0, 1e-4f);
      EXPECT_GE(sigmoid(tint.opacity_logit[i]), 0.8f - 1e-5f);
      ++tinted;
    } else {
      EXPECT_EQ(r1, r0);
      EXPECT_EQ(tint.opacity_logit[i], m.opacity_logit[i]);
    }
  }
  EXPECT_EQ(tinted, fix_->counts[k]);
  EXPECT_EQ(get_ply("/api/model.ply?objects=4&show=isolate").n, fix_->counts[k]);
  EXPECT_EQ(get_ply("/api/model.ply?objects=4&show=remove").n, m.n - fix_->counts[k]);
}

TEST_F(ViewerApi, PanelImagesFollowTheObject) {
  const Scene& sc = session_->scene();
  const int vi = 0, k = 4;
  const View& v = sc.views[vi];
  Image img = get_png("/api/views/0/image.png");
  ASSERT_EQ(img.width, v.width);
  ASSERT_EQ(img.height, v.height);
  Image expect = sc.load_image(vi);
  for (size_t i = 0; i < img.px.size(); ++i) ASSERT_NEAR(img.px[i], expect.px[i], 1.f / 255 + 1e-6f);
  LabelMap gt = load_label_png(sc.root / "gt" / "instances" / (v.stem + ".png"));
  // Overlay: the pixels the red tint changed lie mostly on the object's ground truth.
  Image ov = get_png("/api/views/0/overlay.png?objects=4");
  ASSERT_EQ(ov.width, v.width);
  int changed = 0, on_object = 0, object_px = 0;
  for (int p = 0; p < v.width * v.height; ++p) {
    object_px += gt.v[p] == k;
    if (std::abs(ov.px[p * 3] - img.px[p * 3]) + std::abs(ov.px[p * 3 + 1] - img.px[p * 3 + 1]) > 0.05f) {
      ++changed;
      on_object += gt.v[p] == k;
    }
  }
  ASSERT_GT(object_px, 20) << "object " << k << " should be visible in view 0";
  // Same pixels as the overlay of the session's own mask (reference), and that mask sits on the object
  // (the hand-built model's Gaussians are blobs around SfM points, so it spills over the boundary).
  Image ref = eval::overlay(expect, session_->object_mask(vi, {k}, 0.5f), {});
  for (size_t i = 0; i < ov.px.size(); ++i) ASSERT_NEAR(ov.px[i], ref.px[i], 1.f / 255 + 1e-6f);
  EXPECT_GT(on_object, object_px / 2);
  EXPECT_GT(on_object, 0.3 * changed);
  // The same overlay through the query text.
  Image ov2 = get_png("/api/views/0/overlay.png?text=red%20mug");
  EXPECT_EQ(ov2.px, ov.px);
  // Heatmap of the object opacity: hotter (redder, less blue) on the object than off it.
  Image hm = get_png("/api/views/0/heatmap.png?objects=4");
  double in = 0, out = 0;
  int n_in = 0, n_out = 0;
  for (int p = 0; p < v.width * v.height; ++p) {
    const double t = hm.px[p * 3] - hm.px[p * 3 + 2];
    if (gt.v[p] == k) in += t, ++n_in;
    else out += t, ++n_out;
  }
  EXPECT_GT(in / n_in, out / n_out + 0.3);
  Image px = get_png("/api/views/0/heatmap.png?mode=pixel&text=red%20mug");
  EXPECT_EQ(px.width, v.width);
}

TEST_F(ViewerApi, BadRequestsGet4xxWithMessage) {
  struct Case {
    std::string path;
    int status;
    std::string contains;
  };
  const std::vector<Case> cases = {
      {"/api/query", 400, "text"},
      {"/api/query?text=", 400, "empty"},
      {"/api/query?text=purple%20unicorn%20xyz", 400, "purple unicorn xyz"},
      {"/api/query?text=" + std::string(300, 'a'), 400, "longer"},
      {"/api/export.ply", 400, "objects"},
      {"/api/export.ply?objects=abc", 400, "objects"},
      {"/api/export.ply?objects=1,,2", 400, "objects"},
      {"/api/export.ply?objects=-1", 400, "objects"},
      {"/api/export.ply?objects=99", 404, "99"},
      {"/api/export.ply?objects=0", 404, "0"},
      {"/api/export.ply?objects=1&remove=maybe", 400, "remove"},
      {"/api/model.ply?show=bogus", 400, "show"},
      {"/api/model.ply?show=isolate", 400, "objects"},
      {"/api/views/999/image.png", 404, "999"},
      {"/api/views/x/image.png", 400, "view"},
      {"/api/views/99999999999999/image.png", 400, "view"},
      {"/api/views/0/overlay.png", 400, "objects"},
      {"/api/views/0/overlay.png?objects=1&threshold=nan", 400, "threshold"},
      {"/api/views/0/heatmap.png?mode=pixel", 400, "text"},
      {"/api/views/0/heatmap.png?mode=zzz&objects=1", 400, "mode"},
      {"/api/nothing", 404, "/api/nothing"},
  };
  for (const Case& c : cases) {
    auto r = client().Get(c.path.c_str());
    ASSERT_TRUE(r) << c.path;
    EXPECT_EQ(r->status, c.status) << c.path << ": " << r->body;
    json j = json::parse(r->body, nullptr, false);
    ASSERT_TRUE(j.is_object() && j.contains("error")) << c.path << ": " << r->body;
    EXPECT_NE(j["error"].get<std::string>().find(c.contains), std::string::npos) << c.path << ": " << r->body;
  }
  const std::vector<std::pair<std::string, std::string>> posts = {{"{not json", "JSON"},
                                                                  {"[1,2]", "text"},
                                                                  {"{\"text\": 5}", "text"},
                                                                  {"{}", "text"},
                                                                  {"{\"text\": \"red mug\", \"min_relevancy\": \"x\"}",
                                                                   "min_relevancy"},
                                                                  {"{\"text\": \"red mug\", \"min_relevancy\": 7}",
                                                                   "min_relevancy"}};
  for (auto& [body, contains] : posts) {
    auto r = client().Post("/api/query", body, "application/json");
    ASSERT_TRUE(r) << body;
    EXPECT_EQ(r->status, 400) << body;
    EXPECT_NE(r->body.find(contains), std::string::npos) << body << ": " << r->body;
  }
  // Oversized body: 413, not processed.
  auto big = client().Post("/api/query", "{\"text\": \"" + std::string(10000, 'a') + "\"}", "application/json");
  ASSERT_TRUE(big);
  EXPECT_EQ(big->status, 413);
  EXPECT_NE(big->body.find("too large"), std::string::npos);
  // Garbage on the socket: 400 from the HTTP layer.
  EXPECT_EQ(status_of(raw(port_, "THIS IS NOT HTTP\r\n\r\n")), 400);
  // And the server still answers.
  EXPECT_EQ(get_json("/api/query?text=red%20mug")["chosen"][0]["name"], "red mug");
}

TEST_F(ViewerApi, StaticFilesOnlyFromTheViewerFolder) {
  auto r = client().Get("/");
  ASSERT_TRUE(r);
  EXPECT_EQ(r->status, 200);
  EXPECT_EQ(r->body, "<html>hgs test page</html>");
  EXPECT_EQ(r->get_header_value("Content-Type"), "text/html; charset=utf-8");
  r = client().Get("/assets/app.js");
  ASSERT_TRUE(r);
  EXPECT_EQ(r->status, 200);
  EXPECT_EQ(r->get_header_value("Content-Type"), "text/javascript; charset=utf-8");
  const std::vector<std::string> attacks = {"/../secret.txt",
                                            "/%2e%2e/secret.txt",
                                            "/assets/../../secret.txt",
                                            "/assets/%2e%2e/%2e%2e/secret.txt",
                                            "/..%2fsecret.txt",
                                            "/..%5csecret.txt",
                                            "/%2e%2e%2fsecret.txt",
                                            "//secret.txt",
                                            "/link.txt",
                                            "/assets/..",
                                            fmt::format("/{}", (dir_->path / "secret.txt").string()),
                                            "/secret.txt%00.html",
                                            "/./index.html/../../secret.txt"};
  for (const std::string& a : attacks) {
    const std::string resp = raw(port_, fmt::format("GET {} HTTP/1.1\r\nHost: x\r\nConnection: close\r\n\r\n", a));
    const int st = status_of(resp);
    EXPECT_GE(st, 400) << a;
    EXPECT_LT(st, 500) << a;
    EXPECT_EQ(resp.find("TOP-SECRET"), std::string::npos) << a;
  }
}

TEST(ViewerCli, HelpAndBadInput) {
  RunResult h = run_hgs("view --help");
  EXPECT_EQ(h.exit_code, 0);
  EXPECT_NE(h.out.find("--port"), std::string::npos);
  EXPECT_NE(h.out.find("127.0.0.1"), std::string::npos);
  TempDir d;
  RunResult bad = run_hgs("view '" + (d / "nope").string() + "' '" + (d / "nope.ply").string() + "' --port 0");
  EXPECT_NE(bad.exit_code, 0);
  EXPECT_NE(bad.err.find("error"), std::string::npos);
}

}  // namespace
}  // namespace hgs::test
