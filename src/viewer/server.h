// `hgs view`'s HTTP server: a JSON API over a query::Session plus the browser front end's static files.
// Endpoints (README, "Viewer"): GET /api/scene, /api/objects, /api/query?text=, POST /api/query,
// GET /api/model.ply, /api/export.ply, /api/views/<i>/{image,overlay,heatmap}.png. The session is not
// thread-safe, so every request that touches it holds one mutex. Errors are JSON {"error": "..."} with a 4xx.
#pragma once
#include <cstddef>
#include <filesystem>
#include <memory>
#include <string>
#include <thread>

#include "query/session.h"

namespace httplib {
class Server;
}

namespace hgs::viewer {

struct ServerOptions {
  std::string host = "127.0.0.1";
  int port = 7860;                       // 0 = any free port
  std::filesystem::path static_dir;      // front end; empty = default_static_dir()
  size_t max_body = 64 * 1024;           // request bodies above this get 413
  size_t max_text = 256;                 // longest accepted query text (characters)
};

class Server {
 public:
  Server(query::Session& session, ServerOptions opt);
  // The same routes and handlers installed on `http` (a subclass may feed it requests from memory, as the fuzz
  // harness fuzz/fuzz_viewer.cpp does); start() still binds and serves it.
  Server(query::Session& session, ServerOptions opt, std::unique_ptr<httplib::Server> http);
  ~Server();
  Server(const Server&) = delete;
  Server& operator=(const Server&) = delete;

  // Binds (fails with hgs::Error when the address is taken) and serves on a background thread.
  // Returns the bound port.
  int start();
  void stop();
  // Blocks until the server stops.
  void wait();
  int port() const { return port_; }
  std::string address() const;
  bool has_front_end() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
  std::unique_ptr<httplib::Server> http_;
  std::thread thread_;
  int port_ = 0;
  ServerOptions opt_;
};

}  // namespace hgs::viewer
