#include "viewer/server.h"

#include <fmt/format.h>
#include <httplib.h>
#include <sys/socket.h>

#include <algorithm>
#include <chrono>
#include <mutex>
#include <nlohmann/json.hpp>

#include "core/error.h"
#include "core/fs.h"
#include "core/image.h"
#include "core/utf8.h"
#include "eval/visualize.h"
#include "viewer/display.h"
#include "viewer/gate.h"
#include "viewer/static_files.h"

namespace hgs::viewer {
namespace {
using nlohmann::json;

// A request the client got wrong: answered with `status` and {"error": message}.
struct HttpError : std::runtime_error {
  int status;
  HttpError(int s, const std::string& m) : std::runtime_error(m), status(s) {}
};

void send_json(httplib::Response& res, const json& j, int status = 200) {
  res.status = status;
  // Messages may quote what the client sent: bytes that are not UTF-8 become U+FFFD instead of an exception.
  res.set_content(j.dump(-1, ' ', false, json::error_handler_t::replace), "application/json");
}

std::string png_bytes(const Image& img) {  // img: [H, W, 3] in [0, 1]
  std::vector<uint8_t> px(img.px.size());
  for (size_t i = 0; i < px.size(); ++i) px[i] = uint8_t(std::clamp(img.px[i], 0.f, 1.f) * 255.f + 0.5f);
  std::vector<uint8_t> png = encode_png(img.width, img.height, img.channels, 8, px.data());
  return std::string(png.begin(), png.end());
}

int parse_int(const std::string& s, const char* what) {
  if (s.empty() || s.size() > 9 || !std::all_of(s.begin(), s.end(), [](char c) { return c >= '0' && c <= '9'; }))
    throw HttpError(400, fmt::format("{}: expected a non-negative integer, got \"{}\"", what, s.substr(0, 40)));
  return std::stoi(s);
}

bool parse_bool(const httplib::Request& req, const char* key) {
  if (!req.has_param(key)) return false;
  const std::string v = req.get_param_value(key);
  if (v == "1" || v == "true" || v.empty()) return true;
  if (v == "0" || v == "false") return false;
  throw HttpError(400, fmt::format("{}: expected 0/1/true/false, got \"{}\"", key, v.substr(0, 40)));
}

}  // namespace

struct Server::Impl {
  query::Session& s;
  const ServerOptions& opt;
  std::mutex mu;  // the session (renderer, text cache) is not thread-safe

  Impl(query::Session& session, const ServerOptions& o) : s(session), opt(o) {}

  std::vector<int> known_objects() const {
    std::vector<int> ids;
    const auto& oe = s.objects();
    for (int k = 1; k < oe.num_labels; ++k)
      if (oe.count[k] > 0) ids.push_back(k);
    return ids;
  }

  // "3" or "1,4": every id must be a known object.
  std::vector<int> parse_objects(const std::string& list) const {
    std::vector<int> ids;
    const std::vector<int> known = known_objects();
    size_t start = 0;
    while (start <= list.size()) {
      size_t end = list.find(',', start);
      if (end == std::string::npos) end = list.size();
      const int id = parse_int(list.substr(start, end - start), "objects");
      if (std::find(known.begin(), known.end(), id) == known.end())
        throw HttpError(404, fmt::format("objects: no object {} in the model", id));
      if (std::find(ids.begin(), ids.end(), id) == ids.end()) ids.push_back(id);
      if (ids.size() > 256) throw HttpError(400, "objects: too many ids");
      start = end + 1;
    }
    return ids;
  }

  std::string checked_text(const std::string& t) const {
    if (t.empty()) throw HttpError(400, "text: empty query");
    if (t.size() > opt.max_text) throw HttpError(400, fmt::format("text: longer than {} characters", opt.max_text));
    if (!valid_utf8(t)) throw HttpError(400, "text: not valid UTF-8");
    return t;
  }

  int view_index(const std::string& m) const {
    const int v = parse_int(m, "view");
    if (v >= int(s.scene().views.size()))
      throw HttpError(404, fmt::format("view {}: the scene has {} views", v, s.scene().views.size()));
    return v;
  }

  json object_list() const {
    json a = json::array();
    for (int k : known_objects())
      a.push_back({{"id", k}, {"name", s.object_name(k)}, {"gaussians", s.objects().count[k]}});
    return a;
  }

  json scene_info() const {
    const Scene& sc = s.scene();
    json views = json::array();
    for (const View& v : sc.views) {
      json R = json::array(), t = json::array(), c = json::array();
      for (int r = 0; r < 3; ++r)
        for (int k = 0; k < 3; ++k) R.push_back(v.R(r, k));
      const Eigen::Vector3d cc = v.camera_center();
      for (int r = 0; r < 3; ++r) t.push_back(v.t[r]), c.push_back(cc[r]);
      views.push_back({{"index", v.index},
                       {"name", v.name},
                       {"width", v.width},
                       {"height", v.height},
                       {"fx", v.fx},
                       {"fy", v.fy},
                       {"cx", v.cx},
                       {"cy", v.cy},
                       {"R", R},
                       {"t", t},
                       {"center", c},
                       {"test", v.is_test}});
    }
    const GaussianModel& m = s.model();
    double mean[3] = {0, 0, 0};
    for (int i = 0; i < m.n; ++i)
      for (int c = 0; c < 3; ++c) mean[c] += m.mean[size_t(i) * 3 + c];
    for (double& x : mean) x /= std::max(1, m.n);
    json phrases = json::array();
    for (auto& [k, v] : sc.text_embeddings) phrases.push_back(k);
    return {{"scene", sc.root.filename().string().empty() ? sc.root.parent_path().filename().string()
                                                          : sc.root.filename().string()},
            {"gaussians", m.n},
            {"sh_degree", m.sh_degree},
            {"center", {mean[0], mean[1], mean[2]}},
            {"views", views},
            {"objects", object_list()},
            {"phrases", phrases},
            {"text_source", s.text().source()}};
  }

  json answer(const std::string& text, float min_relevancy) {
    const auto t0 = std::chrono::steady_clock::now();
    std::lock_guard lock(mu);
    query::ObjectAnswer a = s.ask(text, {min_relevancy, 0.5f});
    json results = json::array(), chosen = json::array();
    for (auto& sc : a.scores)
      results.push_back(
          {{"id", sc.object}, {"name", s.object_name(sc.object)}, {"relevancy", sc.relevancy}, {"cosine", sc.cosine}});
    for (int k : a.chosen) chosen.push_back({{"id", k}, {"name", s.object_name(k)}});
    const double secs = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    return {{"text", text}, {"chosen", chosen}, {"results", results}, {"seconds", secs}};
  }

  // The objects a 2D panel request refers to: ?objects=... or the answer to ?text=...
  std::vector<int> panel_objects(const httplib::Request& req) {
    if (req.has_param("objects")) return parse_objects(req.get_param_value("objects"));
    if (req.has_param("text")) {
      const std::string t = checked_text(req.get_param_value("text"));
      std::lock_guard lock(mu);
      return s.ask(t).chosen;
    }
    throw HttpError(400, "give objects=<ids> or text=<query>");
  }

  void view_png(const httplib::Request& req, httplib::Response& res) {
    const int vi = view_index(req.matches[1]);
    const std::string kind = req.matches[2];
    const View& v = s.scene().views[vi];
    Image out;
    if (kind == "image") {
      out = s.scene().load_image(vi);
    } else if (kind == "overlay") {
      std::vector<int> ids = panel_objects(req);
      float thr = 0.5f;
      if (req.has_param("threshold")) {
        try {
          thr = std::stof(req.get_param_value("threshold"));
        } catch (const std::exception&) {
          throw HttpError(400, "threshold: expected a number");
        }
        if (!(thr >= 0.f && thr <= 1.f)) throw HttpError(400, "threshold: expected a number in [0, 1]");
      }
      std::lock_guard lock(mu);
      eval::Mask mask = s.object_mask(vi, ids, thr);
      out = eval::overlay(s.scene().load_image(vi), mask, {});
    } else {  // heatmap
      const std::string mode = req.has_param("mode") ? req.get_param_value("mode") : "object";
      if (mode == "pixel") {
        if (!req.has_param("text")) throw HttpError(400, "mode=pixel needs text=<query>");
        const std::string t = checked_text(req.get_param_value("text"));
        std::lock_guard lock(mu);
        out = eval::heatmap(s.pixel_relevancy(vi, t, query::Relevancy::Objects), v.width, v.height);
      } else if (mode == "object") {
        std::vector<int> ids = panel_objects(req);
        std::lock_guard lock(mu);
        out = eval::heatmap(s.object_opacity(vi, ids), v.width, v.height, 0.f, 1.f);
      } else {
        throw HttpError(400, "mode: expected object or pixel");
      }
    }
    res.set_content(png_bytes(out), "image/png");
  }

  void model_ply(const httplib::Request& req, httplib::Response& res, bool download) {
    DisplayOptions d;
    if (req.has_param("objects")) d.objects = parse_objects(req.get_param_value("objects"));
    std::string name;
    if (download) {
      if (d.objects.empty()) throw HttpError(400, "export needs objects=<ids>");
      const bool remove = parse_bool(req, "remove");
      d.show = remove ? Show::remove : Show::isolate;
      d.keep_extras = true;
      std::string ids;
      for (int k : d.objects) {
        if (!ids.empty()) ids += '-';
        ids += std::to_string(k);  // appended apart: GCC 12 reports a false -Wrestrict on "-" + std::to_string(k)
      }
      name = remove ? "scene-without-" + ids + ".ply" : "object-" + ids + ".ply";
    } else {
      const std::string show = req.has_param("show") ? req.get_param_value("show") : "all";
      if (show == "all") d.show = Show::all;
      else if (show == "isolate") d.show = Show::isolate;
      else if (show == "remove") d.show = Show::remove;
      else throw HttpError(400, "show: expected all, isolate or remove");
      if (d.show != Show::all && d.objects.empty()) throw HttpError(400, "show=" + show + " needs objects=<ids>");
      d.tint = parse_bool(req, "tint");
    }
    GaussianModel m = display_model(s.model(), d);
    if (m.n == 0) throw HttpError(409, "no Gaussians left to show for this selection");
    res.set_content(ply_bytes(m), "application/octet-stream");
    if (download) res.set_header("Content-Disposition", "attachment; filename=\"" + name + "\"");
    res.set_header("Cache-Control", "no-store");
  }
};

namespace {
std::unique_ptr<GatedHttpServer> gated(const ServerOptions& o) {
  GateOptions g;
  g.threads = std::max(1, o.threads);
  g.read_timeout_s = o.read_timeout_s, g.write_timeout_s = o.write_timeout_s;
  g.request_timeout_s = o.request_timeout_s;
  g.keep_alive_s = o.keep_alive_s, g.keep_alive_max = std::max(1, o.keep_alive_max);
  g.max_connections = std::max<size_t>(1, o.max_connections);
  // Room for the largest request the limits accept (request line, header, body), so that the worker, not the
  // gate, refuses a larger one with its status.
  g.max_request_bytes = o.max_body + o.max_header_bytes + 16 * 1024;
  return std::make_unique<GatedHttpServer>(g);
}
}  // namespace

Server::Server(query::Session& session, ServerOptions opt) : Server(session, opt, gated(opt)) {}

Server::Server(query::Session& session, ServerOptions opt, std::unique_ptr<httplib::Server> http)
    : http_(std::move(http)), opt_(std::move(opt)) {
  if (opt_.static_dir.empty()) opt_.static_dir = default_static_dir();
  impl_ = std::make_unique<Impl>(session, opt_);
  Impl& I = *impl_;
  httplib::Server& svr = *http_;

  // Every handler runs under this guard: client errors -> 4xx, hgs::Error (bad phrase, bad data) -> 400.
  auto guard = [](auto fn) {
    return [fn](const httplib::Request& req, httplib::Response& res) {
      try {
        fn(req, res);
      } catch (const HttpError& e) {
        send_json(res, {{"error", e.what()}}, e.status);
      } catch (const Error& e) {
        send_json(res, {{"error", e.what()}}, 400);
      } catch (const json::exception& e) {
        send_json(res, {{"error", std::string("bad JSON: ") + e.what()}}, 400);
      } catch (const std::exception& e) {
        send_json(res, {{"error", std::string("internal error: ") + e.what()}}, 500);
      }
    };
  };

  // Limits set explicitly (not the library's defaults): body size, timeouts, keep-alive, workers.
  svr.set_payload_max_length(opt_.max_body);
  svr.set_read_timeout(opt_.read_timeout_s, 0);
  svr.set_write_timeout(opt_.write_timeout_s, 0);
  svr.set_keep_alive_timeout(opt_.keep_alive_s);
  svr.set_keep_alive_max_count(size_t(std::max(1, opt_.keep_alive_max)));
  gate_ = dynamic_cast<GatedHttpServer*>(http_.get());
  const size_t workers = size_t(std::max(1, opt_.threads));
  if (!gate_) svr.new_task_queue = [workers] { return new httplib::ThreadPool(workers); };
  // SO_REUSEADDR only: httplib's default SO_REUSEPORT would let a second server share a port in use.
  svr.set_socket_options([this](socket_t sock) {
    int yes = 1;
    ::setsockopt(sock, SOL_SOCKET, SO_REUSEADDR, reinterpret_cast<void*>(&yes), sizeof yes);
    listen_fd_ = int(sock);
  });
  svr.set_error_handler([](const httplib::Request& req, httplib::Response& res) {
    if (!res.body.empty()) return;
    std::string msg = res.status == 413   ? "request body too large"
                      : res.status == 404 ? "not found: " + req.path
                                          : fmt::format("HTTP {}", res.status);
    send_json(res, {{"error", msg}}, res.status);
  });

  svr.set_pre_routing_handler([this](const httplib::Request& req, httplib::Response& res) {
    size_t bytes = 0;
    for (const auto& [k, v] : req.headers) bytes += k.size() + v.size() + 4;
    if (req.headers.size() <= opt_.max_headers && bytes <= opt_.max_header_bytes)
      return httplib::Server::HandlerResponse::Unhandled;
    send_json(res,
              {{"error", fmt::format("request header fields too large ({} fields, {} bytes; at most {} and {})",
                                     req.headers.size(), bytes, opt_.max_headers, opt_.max_header_bytes)}},
              431);
    res.set_header("Connection", "close");
    return httplib::Server::HandlerResponse::Handled;
  });

  svr.Get("/api/scene",
          guard([&I](const httplib::Request&, httplib::Response& res) { send_json(res, I.scene_info()); }));
  svr.Get("/api/objects", guard([&I](const httplib::Request&, httplib::Response& res) {
            send_json(res, {{"objects", I.object_list()}});
          }));
  svr.Get("/api/query", guard([&I](const httplib::Request& req, httplib::Response& res) {
            if (!req.has_param("text")) throw HttpError(400, "missing text=<query>");
            send_json(res, I.answer(I.checked_text(req.get_param_value("text")), 0.f));
          }));
  svr.Post("/api/query", guard([&I](const httplib::Request& req, httplib::Response& res) {
             const json body = json::parse(req.body);
             if (!body.is_object() || !body.contains("text") || !body["text"].is_string())
               throw HttpError(400, "expected a JSON object {\"text\": \"...\"}");
             float min_rel = 0.f;
             if (body.contains("min_relevancy")) {
               if (!body["min_relevancy"].is_number()) throw HttpError(400, "min_relevancy: expected a number");
               min_rel = body["min_relevancy"].get<float>();
               if (!(min_rel >= 0.f && min_rel <= 1.f))
                 throw HttpError(400, "min_relevancy: expected a number in [0, 1]");
             }
             send_json(res, I.answer(I.checked_text(body["text"].get<std::string>()), min_rel));
           }));
  svr.Get("/api/model.ply",
          guard([&I](const httplib::Request& req, httplib::Response& res) { I.model_ply(req, res, false); }));
  svr.Get("/api/export.ply",
          guard([&I](const httplib::Request& req, httplib::Response& res) { I.model_ply(req, res, true); }));
  svr.Get(R"(/api/views/([^/]+)/(image|overlay|heatmap)\.png)",
          guard([&I](const httplib::Request& req, httplib::Response& res) { I.view_png(req, res); }));
  svr.Get("/api/.*", guard([](const httplib::Request& req, httplib::Response&) {
            throw HttpError(404, "no such API endpoint: " + req.path);
          }));

  // Static front end: only files inside the viewer folder.
  const std::filesystem::path root = opt_.static_dir;
  svr.Get("/.*", guard([root](const httplib::Request& req, httplib::Response& res) {
            auto file = resolve_static(root, req.path);
            if (!file) {
              if (req.path == "/" || req.path == "/index.html")
                throw HttpError(404,
                                fmt::format("the viewer front end is not built ({} has no index.html); the JSON API "
                                            "under /api/ works",
                                            root.string()));
              throw HttpError(404, "not found: " + req.path);
            }
            std::vector<uint8_t> b = read_file_bytes(*file);
            res.set_content(std::string(b.begin(), b.end()), mime_type(*file));
          }));
}

Server::~Server() { stop(); }

int Server::start() {
  if (opt_.port == 0) {
    port_ = http_->bind_to_any_port(opt_.host);
    if (port_ <= 0) fail("cannot bind {} on any port", opt_.host);
  } else {
    if (!http_->bind_to_port(opt_.host, opt_.port))
      fail("cannot bind {}:{} (address in use or not local?)", opt_.host, opt_.port);
    port_ = opt_.port;
  }
  // Linux updates the backlog of a listening socket on a second listen(): the library listens with 5, which
  // drops connection bursts (clients then wait for a SYN retransmit, 1 s).
  if (listen_fd_ >= 0) ::listen(listen_fd_, opt_.listen_backlog);
  thread_ = std::thread([this] { http_->listen_after_bind(); });
  // Wait until the accept loop runs: a stop() before that would be lost and join() would hang.
  for (int i = 0; i < 10000 && !http_->is_running(); ++i) std::this_thread::sleep_for(std::chrono::milliseconds(1));
  if (!http_->is_running()) {
    stop();
    fail("the HTTP server on {}:{} did not start", opt_.host, port_);
  }
  return port_;
}

void Server::stop() {
  if (http_) http_->stop();
  if (thread_.joinable()) thread_.join();
  if (gate_) gate_->shutdown_gate();
}

void Server::wait() {
  if (thread_.joinable()) thread_.join();
}

std::string Server::address() const {
  const bool v6 = opt_.host.find(':') != std::string::npos;
  return fmt::format("http://{}:{}/", v6 ? "[" + opt_.host + "]" : opt_.host, port_);
}

bool Server::has_front_end() const { return resolve_static(opt_.static_dir, "/index.html").has_value(); }

}  // namespace hgs::viewer
