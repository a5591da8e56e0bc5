// `hgs view SCENE MODEL [--host 127.0.0.1] [--port 7860]`: serves the browser viewer (splat rendering, text
// queries, isolate/remove/download of objects, 2D overlay and heatmap panel) and its JSON API
// (src/viewer/server.h, README "Viewer") until interrupted.
#include <fmt/format.h>

#include "cli/command.h"
#include "core/error.h"
#include "query/session.h"
#include "viewer/server.h"
#include "viewer/static_files.h"

namespace hgs::cli {
namespace {
namespace fs = std::filesystem;

struct ViewArgs {
  std::string scene, model, host = "127.0.0.1", clip, static_dir;
  int port = 7860, downscale = 1, threads = 0;
};

void run_view(const ViewArgs& a) {
  set_threads(a.threads);
  fs::path ply = a.model;
  if (fs::is_directory(ply)) ply /= "point_cloud.ply";
  query::Session session(a.scene, ply, a.downscale, a.clip);
  viewer::ServerOptions opt;
  opt.host = a.host;
  opt.port = a.port;
  opt.static_dir = a.static_dir.empty() ? viewer::default_static_dir() : fs::path(a.static_dir);
  viewer::Server server(session, opt);
  server.start();
  if (!server.has_front_end())
    fmt::print(stderr, "hgs view: warning: no front end in {} (build it with scripts/build); only /api/ works\n",
               opt.static_dir.string());
  if (a.host != "127.0.0.1" && a.host != "localhost" && a.host != "::1")
    fmt::print(stderr, "hgs view: warning: listening on {} makes the viewer reachable from other machines\n", a.host);
  fmt::print("hgs view: {} Gaussians, {} objects, {} views; serving at {}  (Ctrl-C to stop)\n", session.model().n,
             session.objects().num_labels > 0 ? session.objects().num_labels - 1 : 0, session.scene().views.size(),
             server.address());
  std::fflush(stdout);
  server.wait();
}

CommandRegistration reg(
    {"view", "Serve the web viewer: splats in the browser, text queries, object export", 70, [](CLI::App& sub) {
       auto a = std::make_shared<ViewArgs>();
       sub.add_option("SCENE", a->scene, "Scene folder")->required();
       sub.add_option("MODEL", a->model, "Trained hybrid model folder (point_cloud.ply) or PLY file")->required();
       sub.add_option("--host", a->host, "Address to bind (loopback by default)")->capture_default_str();
       sub.add_option("--port", a->port, "Port (0 = any free port)")
           ->check(CLI::Range(0, 65535))
           ->capture_default_str();
       sub.add_option("--clip", a->clip,
                      "OpenCLIP weights (.safetensors) to embed any query (else SCENE/text_embeddings.json)");
       sub.add_option("--downscale", a->downscale, "Integer image downscale (as used for training)")
           ->check(CLI::Range(1, 64));
       sub.add_option("--static", a->static_dir, "Front-end folder (default: viewer/ beside the hgs binary)");
       add_threads_option(sub, a->threads, "Worker threads for rendering");
       return [a] { run_view(*a); };
     }});

}  // namespace
}  // namespace hgs::cli
