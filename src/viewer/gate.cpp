// GatedHttpServer (gate.h): the gate thread's poll loop over waiting connections, the completeness test of a
// buffered request, and the stream a worker answers through (buffered bytes first, then the socket).
#include "viewer/gate.h"

#include <arpa/inet.h>
#include <fcntl.h>
#include <netinet/in.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cstring>
#include <string_view>

#include "core/error.h"

namespace hgs::viewer {
namespace {
using Clock = std::chrono::steady_clock;

double seconds_since(Clock::time_point t) { return std::chrono::duration<double>(Clock::now() - t).count(); }

char lower(char c) { return (c >= 'A' && c <= 'Z') ? char(c - 'A' + 'a') : c; }

// The value of header `name` (lower case) in a header block, or "" (first occurrence).
std::string_view header_value(std::string_view head, std::string_view name) {
  size_t line = head.find("\r\n");
  while (line != std::string_view::npos && line + 2 < head.size()) {
    const size_t start = line + 2, end = std::min(head.find("\r\n", start), head.size());
    const std::string_view l = head.substr(start, end - start);
    if (l.size() > name.size() && l[name.size()] == ':' &&
        std::equal(name.begin(), name.end(), l.begin(), [](char a, char b) { return a == lower(b); })) {
      std::string_view v = l.substr(name.size() + 1);
      while (!v.empty() && (v.front() == ' ' || v.front() == '\t')) v.remove_prefix(1);
      while (!v.empty() && (v.back() == ' ' || v.back() == '\t')) v.remove_suffix(1);
      return v;
    }
    line = end < head.size() ? end : std::string_view::npos;
  }
  return {};
}

bool iequals(std::string_view a, std::string_view b) {
  return a.size() == b.size() &&
         std::equal(a.begin(), a.end(), b.begin(), [](char x, char y) { return lower(x) == lower(y); });
}

void close_fd(int fd) {
  ::shutdown(fd, SHUT_RDWR);
  ::close(fd);
}

// What a worker reads and writes through: the bytes the gate buffered, then the socket (reads wait at most
// read_timeout_s for a byte). Bytes read past the end of this request stay buffered for the next one. What the
// socket does not take at once is kept in `out` for the gate to send, while the held total (`pending`, shared
// by all connections) stays under max_pending_bytes; past it the worker waits for the client (write_timeout_s
// without progress: the answer is abandoned).
class GateStream : public httplib::Stream {
 public:
  GateStream(int fd, std::string buf, const GateOptions& opt, std::atomic<size_t>& pending)
      : fd_(fd), buf_(std::move(buf)), opt_(opt), pending_(pending) {}
  bool is_readable() const override { return pos_ < buf_.size() || wait(POLLIN, opt_.read_timeout_s * 1000); }
  bool is_writable() const override { return wait(POLLOUT, opt_.write_timeout_s * 1000); }
  ssize_t read(char* ptr, size_t size) override {
    if (pos_ == buf_.size()) {
      buf_.clear(), pos_ = 0;
      if (!wait(POLLIN, opt_.read_timeout_s * 1000)) return -1;
      char chunk[16384];
      const ssize_t n = ::recv(fd_, chunk, sizeof chunk, MSG_DONTWAIT);
      if (n <= 0) return n;
      buf_.assign(chunk, size_t(n));
    }
    const size_t n = std::min(size, buf_.size() - pos_);
    std::memcpy(ptr, buf_.data() + pos_, n);
    pos_ += n;
    return ssize_t(n);
  }
  ssize_t write(const char* ptr, size_t size) override {
    size_t done = 0;
    while (done < size) {
      if (!out.empty()) {  // keep the order: once something is held, the rest is held too
        if (pending_.load() + (size - done) > opt_.max_pending_bytes && !flush()) return -1;
        if (!out.empty()) {
          out.append(ptr + done, size - done);
          pending_ += size - done;
          return ssize_t(size);
        }
      }
      const ssize_t n = ::send(fd_, ptr + done, size - done, MSG_NOSIGNAL | MSG_DONTWAIT);
      if (n > 0) {
        done += size_t(n);
      } else if (n < 0 && errno != EAGAIN && errno != EWOULDBLOCK && errno != EINTR) {
        return -1;
      } else if (pending_.load() + (size - done) <= opt_.max_pending_bytes) {
        out.append(ptr + done, size - done);
        pending_ += size - done;
        return ssize_t(size);
      } else if (!wait(POLLOUT, opt_.write_timeout_s * 1000)) {
        return -1;
      }
    }
    return ssize_t(size);
  }
  // Sends what is held, waiting for the client (false: no progress for write_timeout_s, or an error).
  bool flush() {
    while (!out.empty()) {
      const ssize_t n = ::send(fd_, out.data(), out.size(), MSG_NOSIGNAL | MSG_DONTWAIT);
      if (n > 0) {
        out.erase(0, size_t(n));
        pending_ -= size_t(n);
      } else if ((n < 0 && errno != EAGAIN && errno != EWOULDBLOCK && errno != EINTR) ||
                 !wait(POLLOUT, opt_.write_timeout_s * 1000)) {
        return false;
      }
    }
    return true;
  }
  void get_remote_ip_and_port(std::string& ip, int& port) const override { address(true, ip, port); }
  void get_local_ip_and_port(std::string& ip, int& port) const override { address(false, ip, port); }
  socket_t socket() const override { return fd_; }
  std::string rest() const { return buf_.substr(pos_); }
  std::string out;  // answer bytes the socket has not taken yet (counted in pending_)

 private:
  bool wait(short events, int ms) const {
    pollfd p{fd_, events, 0};
    int r;
    do r = ::poll(&p, 1, std::max(ms, 0));
    while (r < 0 && errno == EINTR);
    return r > 0 && (p.revents & (events | POLLHUP | POLLERR));
  }
  void address(bool peer, std::string& ip, int& port) const {
    sockaddr_storage a{};
    socklen_t len = sizeof a;
    const int r = peer ? ::getpeername(fd_, reinterpret_cast<sockaddr*>(&a), &len)
                       : ::getsockname(fd_, reinterpret_cast<sockaddr*>(&a), &len);
    char s[INET6_ADDRSTRLEN] = "";
    port = 0;
    if (r == 0 && a.ss_family == AF_INET) {
      const auto* v4 = reinterpret_cast<const sockaddr_in*>(&a);
      ::inet_ntop(AF_INET, &v4->sin_addr, s, sizeof s);
      port = ntohs(v4->sin_port);
    } else if (r == 0 && a.ss_family == AF_INET6) {
      const auto* v6 = reinterpret_cast<const sockaddr_in6*>(&a);
      ::inet_ntop(AF_INET6, &v6->sin6_addr, s, sizeof s);
      port = ntohs(v6->sin6_port);
    }
    ip = s;
  }
  int fd_;
  std::string buf_;
  size_t pos_ = 0;
  const GateOptions& opt_;
  std::atomic<size_t>& pending_;
};

// The accept thread runs httplib's tasks inline: each is only a hand-over to the gate.
struct InlineQueue : httplib::TaskQueue {
  void enqueue(std::function<void()> fn) override { fn(); }
  void shutdown() override {}
};
}  // namespace

bool request_complete(const std::string& buf, size_t max_bytes) {
  if (buf.size() >= max_bytes) return true;
  const size_t end = buf.find("\r\n\r\n");
  if (end == std::string::npos) return false;
  const std::string_view head(buf.data(), end + 2), body(buf.data() + end + 4, buf.size() - end - 4);
  if (iequals(header_value(head, "expect"), "100-continue")) return true;
  if (iequals(header_value(head, "transfer-encoding"), "chunked"))
    return body.size() >= 5 && (body.substr(0, 3) == "0\r\n" || body.find("\r\n0\r\n") != std::string_view::npos) &&
           body.substr(body.size() - 4) == "\r\n\r\n";
  const std::string_view cl = header_value(head, "content-length");
  if (cl.empty()) return true;
  size_t n = 0;
  for (char c : cl) {
    if (c < '0' || c > '9' || n > max_bytes) return true;  // malformed or huge: the worker refuses it
    n = n * 10 + size_t(c - '0');
  }
  return n >= max_bytes || body.size() >= n;
}

struct GatedHttpServer::Conn {
  int fd = -1;
  std::string buf;                       // bytes of the next request read so far
  std::string out;                       // answer bytes still to send (counted in pending_)
  bool close_after = false;              // close once `out` is sent
  int served = 0;                        // requests answered on this connection
  Clock::time_point since, first, last;  // entered the gate (or last sent a byte); first / last request byte
};

GatedHttpServer::GatedHttpServer(GateOptions opt) : opt_(opt) {
  if (::pipe2(wake_, O_CLOEXEC | O_NONBLOCK) != 0)
    fail("viewer: cannot create the gate's pipe: {}", std::strerror(errno));
  workers_ = std::make_unique<httplib::ThreadPool>(size_t(std::max(1, opt_.threads)));
  new_task_queue = [] { return new InlineQueue; };
  gate_ = std::thread([this] { gate_loop(); });
}

GatedHttpServer::~GatedHttpServer() { shutdown_gate(); }

size_t GatedHttpServer::waiting() const { return waiting_.load(); }

bool GatedHttpServer::process_and_close_socket(socket_t sock) {
  if (stopping_) {
    close_fd(sock);
    return false;
  }
  Conn c;
  c.fd = sock;
  c.since = Clock::now();
  admit(std::move(c));
  return true;
}

void GatedHttpServer::admit(Conn c) {
  {
    std::lock_guard<std::mutex> lock(mu_);
    if (stopping_) {
      pending_ -= c.out.size();
      close_fd(c.fd);
      return;
    }
    incoming_.push_back(std::move(c));
  }
  const char b = 1;
  [[maybe_unused]] const ssize_t r = ::write(wake_[1], &b, 1);  // a full pipe already wakes the gate
}

void GatedHttpServer::gate_loop() {
  std::vector<Conn> conns;
  std::vector<pollfd> fds;
  while (!stopping_) {
    fds.assign(1, pollfd{wake_[0], POLLIN, 0});
    for (const Conn& c : conns) fds.push_back(pollfd{c.fd, short(c.out.empty() ? POLLIN : POLLOUT), 0});
    ::poll(fds.data(), fds.size(), 100);  // the timeout bounds how late a deadline is noticed
    if (fds[0].revents) {
      char drain[256];
      while (::read(wake_[0], drain, sizeof drain) > 0) {
      }
    }
    std::vector<Conn> keep, ready;
    const auto now = Clock::now();
    for (size_t i = 0; i < conns.size(); ++i) {
      Conn& c = conns[i];
      bool drop = false;
      if (!c.out.empty()) {  // a slow reader: send what it takes, drop it when it takes nothing for too long
        if (fds[i + 1].revents) {
          const ssize_t n = ::send(c.fd, c.out.data(), c.out.size(), MSG_NOSIGNAL | MSG_DONTWAIT);
          if (n > 0) {
            c.out.erase(0, size_t(n));
            pending_ -= size_t(n);
            c.since = now;
          } else if (n < 0 && errno != EAGAIN && errno != EWOULDBLOCK && errno != EINTR) {
            drop = true;
          }
        }
        if (!drop && c.out.empty() && c.close_after) drop = true;
        if (!drop && !c.out.empty() && seconds_since(c.since) <= opt_.write_timeout_s) {
          keep.push_back(std::move(c));
          continue;
        }
        if (drop || !c.out.empty()) {
          pending_ -= c.out.size();
          close_fd(c.fd);
          continue;
        }
        c.since = c.first = c.last = now;  // answered: now idle, or a pipelined request starts its clock
      } else if (fds[i + 1].revents) {
        char chunk[16384];
        const ssize_t n = ::recv(c.fd, chunk, sizeof chunk, MSG_DONTWAIT);
        if (n == 0 || (n < 0 && errno != EAGAIN && errno != EWOULDBLOCK && errno != EINTR)) {
          drop = true;  // closed by the client, or an error
        } else if (n > 0) {
          if (c.buf.empty()) c.first = now;
          c.last = now;
          c.buf.append(chunk, size_t(n));
        }
      }
      if (!drop && !c.buf.empty() && request_complete(c.buf, opt_.max_request_bytes)) {
        ready.push_back(std::move(c));
        continue;
      }
      const bool idle = c.buf.empty();
      const double limit = c.served == 0 ? opt_.read_timeout_s : opt_.keep_alive_s;
      const bool late =
          idle ? seconds_since(c.since) > limit
               : (seconds_since(c.first) > opt_.request_timeout_s || seconds_since(c.last) > opt_.read_timeout_s);
      if (drop || late) {
        if (late && !idle) {
          static constexpr std::string_view k408 =
              "HTTP/1.1 408 Request Timeout\r\nContent-Type: application/json\r\nContent-Length: 46\r\n"
              "Connection: close\r\n\r\n{\"error\": \"request not complete within limits\"}";
          [[maybe_unused]] const ssize_t w = ::send(c.fd, k408.data(), k408.size(), MSG_NOSIGNAL | MSG_DONTWAIT);
        }
        close_fd(c.fd);
        continue;
      }
      keep.push_back(std::move(c));
    }
    {
      std::lock_guard<std::mutex> lock(mu_);
      for (Conn& c : incoming_) {
        if (keep.size() >= opt_.max_connections) {
          pending_ -= c.out.size();
          close_fd(c.fd);
          continue;
        }
        if (c.out.empty() && !c.buf.empty() && request_complete(c.buf, opt_.max_request_bytes)) {
          ready.push_back(std::move(c));  // a pipelined request already buffered
        } else {
          if (!c.buf.empty()) c.first = c.last = now;
          keep.push_back(std::move(c));
        }
      }
      incoming_.clear();
    }
    conns = std::move(keep);
    waiting_ = conns.size();
    for (Conn& c : ready) workers_->enqueue([this, c = std::move(c)]() mutable { serve(std::move(c)); });
  }
  for (Conn& c : conns) {
    pending_ -= c.out.size();
    close_fd(c.fd);
  }
  waiting_ = 0;
}

void GatedHttpServer::serve(Conn c) {
  GateStream strm(c.fd, std::move(c.buf), opt_, pending_);
  const bool last = c.served + 1 >= std::max(1, opt_.keep_alive_max);
  bool closed = false;
  const bool ok = process_request(strm, last, closed, nullptr);
  c.close_after = !ok || closed || last;
  if ((c.close_after && strm.out.empty()) || stopping_) {
    pending_ -= strm.out.size();
    close_fd(c.fd);
    return;
  }
  c.buf = strm.rest();
  c.out = std::move(strm.out);
  c.served += 1;
  c.since = Clock::now();
  admit(std::move(c));
}

void GatedHttpServer::shutdown_gate() {
  {
    std::lock_guard<std::mutex> lock(mu_);
    if (stopping_.exchange(true)) return;
    for (Conn& c : incoming_) close_fd(c.fd);
    incoming_.clear();
  }
  const char b = 1;
  [[maybe_unused]] const ssize_t r = ::write(wake_[1], &b, 1);
  if (gate_.joinable()) gate_.join();
  if (workers_) workers_->shutdown();
  ::close(wake_[0]);
  ::close(wake_[1]);
}

}  // namespace hgs::viewer
