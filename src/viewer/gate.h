// A front stage for cpp-httplib's server that keeps slow clients off the worker threads (Slowloris).
//
// cpp-httplib 0.11 gives each accepted connection one worker for as long as it is open: a client that drips its
// request one byte at a time holds that worker indefinitely (the read timeout restarts with every byte), so 32
// such clients stall a 32-worker server. GatedHttpServer instead hands every connection to one gate thread
// (poll(2) over all waiting sockets) that reads the request into memory without blocking; only a complete
// request (header, and the body its Content-Length or chunked framing announces) goes to a worker, which
// answers it from memory and the socket, then returns the connection to the gate for its next keep-alive
// request. Slow readers likewise: what a worker cannot send at once is kept in memory (up to
// `max_pending_bytes` over all connections; beyond that the worker waits) and the gate sends it as the client
// reads. A connection is dropped (408 when it had sent part of a request) when it sends nothing for
// `read_timeout_s`, when a request is not complete `request_timeout_s` after its first byte, when an idle
// keep-alive connection waits longer than `keep_alive_s`, or when it reads nothing of an answer for
// `write_timeout_s`. More than `max_connections` waiting connections: the newest is closed.
//
// Written by hand because no Debian-packaged HTTP library does this for us: cpp-httplib has no total request
// deadline or asynchronous reading, and moving the viewer to another server library (Boost.Beast, libmicrohttpd)
// would be a rewrite of its routes for this one property.
#pragma once
#include <httplib.h>

#include <atomic>
#include <cstddef>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

namespace hgs::viewer {

struct GateOptions {
  int threads = 32;  // workers answering complete requests
  int read_timeout_s = 5, write_timeout_s = 5;
  int request_timeout_s = 10;  // a whole request (header and body) must arrive within this after its first byte
  int keep_alive_s = 2, keep_alive_max = 100;
  size_t max_connections = 512;           // connections waiting in the gate at once
  size_t max_request_bytes = 96 * 1024;   // buffered per request before a worker takes it anyway (it refuses it)
  size_t max_pending_bytes = 256u << 20;  // unsent answers held for slow readers, all connections together
};

// Whether `buf` holds a complete HTTP request (header + announced body), or enough that waiting longer cannot
// help: an `Expect: 100-continue` header (the worker answers it), an announced body over `max_bytes`, or `buf`
// itself over `max_bytes`. Exposed for the unit test.
bool request_complete(const std::string& buf, size_t max_bytes);

class GatedHttpServer : public httplib::Server {
 public:
  explicit GatedHttpServer(GateOptions opt);
  ~GatedHttpServer() override;
  // Closes every waiting connection and joins the gate and the workers; after httplib's stop(). Idempotent.
  void shutdown_gate();
  size_t waiting() const;  // connections in the gate now

 private:
  struct Conn;
  bool process_and_close_socket(socket_t sock) override;  // accept thread: hand the socket to the gate
  void admit(Conn c);
  void gate_loop();
  void serve(Conn c);

  GateOptions opt_;
  int wake_[2] = {-1, -1};  // pipe that wakes the gate's poll when a connection comes back
  mutable std::mutex mu_;
  std::vector<Conn> incoming_;
  std::atomic<size_t> waiting_{0};
  std::atomic<size_t> pending_{0};  // bytes of answers held for slow readers
  std::atomic<bool> stopping_{false};
  std::unique_ptr<httplib::ThreadPool> workers_;
  std::thread gate_;
};

}  // namespace hgs::viewer
