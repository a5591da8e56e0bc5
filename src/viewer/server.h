// `hgs view`'s HTTP server: a JSON API over a query::Session plus the browser front end's static files.
// Endpoints (README, "Viewer"): GET /api/scene, /api/objects, /api/query?text=, POST /api/query,
// GET /api/model.ply, /api/export.ply, /api/views/<i>/{image,overlay,heatmap}.png. The session is not
// thread-safe, so every request that touches it holds one mutex. Errors are JSON {"error": "..."} with a 4xx;
// every JSON reply is valid UTF-8 (bytes a client sent that are not are replaced by U+FFFD in messages), and
// query texts must be valid UTF-8. Load figures and limits: docs/reliability.md ("The viewer under load").
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

class GatedHttpServer;

struct ServerOptions {
  std::string host = "127.0.0.1";
  int port = 7860;                   // 0 = any free port
  std::filesystem::path static_dir;  // front end; empty = default_static_dir()
  size_t max_body = 64 * 1024;       // request bodies above this get 413
  size_t max_text = 256;             // longest accepted query text (bytes of UTF-8)
  // Connection limits (cpp-httplib 0.11: request line and each header line are capped at 8 kB by the library).
  // Connections wait in the gate (viewer/gate.h) until a whole request has arrived, so `threads` bounds the
  // requests answered at once, not the clients connected: slow clients hold no worker. A connection is dropped
  // when it sends nothing for `read_timeout_s`, when a request is not whole `request_timeout_s` after its first
  // byte, or when more than `max_connections` wait (docs/reliability.md).
  int threads = 32;
  int read_timeout_s = 5, write_timeout_s = 5, request_timeout_s = 10;
  int keep_alive_s = 2, keep_alive_max = 100;  // an idle keep-alive connection is closed after keep_alive_s
  size_t max_connections = 512;
  int listen_backlog = 128;  // pending connections (the library's own default is 5)
  // Requests with more header fields or header bytes get 431. The library has read them by then (0.11 has
  // no such limit of its own): this bounds what a handler sees, not what one connection may send.
  size_t max_headers = 64, max_header_bytes = 16 * 1024;
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
  int listen_fd_ = -1;               // the listening socket (its backlog is raised after bind)
  GatedHttpServer* gate_ = nullptr;  // http_ when it is the gated server (the default), else null
  ServerOptions opt_;
};

}  // namespace hgs::viewer
