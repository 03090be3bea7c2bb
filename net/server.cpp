// The node's websocketpp (standalone asio) server: with net/ws_client.cpp, the only translation
// units that include websocketpp (each costs ~15 s and 0.5 GB to compile).
#include "net/server.h"

#include <atomic>
#include <condition_variable>
#include <cstdio>
#include <deque>
#include <fstream>
#include <map>
#include <mutex>
#include <set>
#include <sstream>
#include <thread>
#include <array>
#include <ctime>

#include <netinet/in.h>
#include <netinet/tcp.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <sys/socket.h>

#include <caf/all.hpp>

#include <websocketpp/config/asio.hpp>  // asio (plain) and asio_tls
#include <websocketpp/server.hpp>

#include "net/http.h"
#include "net/link_meter.h"
#include "net/tcp_stats.h"
#include "net/tls.h"

namespace tessera {

using websocketpp::connection_hdl;

// Everything below is a template over websocketpp's config: websocketpp::config::asio (plain
// HTTP and WebSocket) or websocketpp::config::asio_tls (HTTPS and WSS, ServerOptions::tls_*).
// A connection's get_raw_socket() is its TCP socket either way, get_socket() the stream its
// bytes go through (the TCP socket, or the TLS stream over it).

namespace {

// Ends a deferred HTTP response's connection (an MJPEG stream's or a streamed file's).
template <class ConnectionPtr>
void close_socket(const ConnectionPtr& con) {
  asio::error_code ec;
  con->get_raw_socket().shutdown(asio::ip::tcp::socket::shutdown_both, ec);
  con->get_raw_socket().close(ec);
}

// One MJPEG viewer: the HTTP connection's response is deferred and its socket written
// directly; a slow viewer gets the latest frame (older pending ones are replaced).
template <class Config>
struct MjpegStream : std::enable_shared_from_this<MjpegStream<Config>> {
  typename websocketpp::server<Config>::connection_ptr con;
  std::atomic<size_t>* live = nullptr;  // the server's count of open streams
  bool writing = false, dead = false;
  std::shared_ptr<const std::vector<uint8_t>> current, pending;
  uint32_t pending_frame = 0;  // the client's frame number of `pending` (X-Tessera-Frame)
  std::string part_header;
  std::string extra_headers;  // further header lines of the response ("Name: value\r\n" each)
  static constexpr const char* kBoundary = "tesseraframe";

  void push(std::shared_ptr<const std::vector<uint8_t>> jpeg, uint32_t frame) {
    if (dead) return;
    pending = std::move(jpeg);
    pending_frame = frame;
    if (!writing) write_next();
  }
  // Each part ends with the next boundary: a browser shows a part of a multipart stream only
  // once its end is known, so the newest frame must not wait for the one after it.
  void write_next() {
    if (dead || !pending) return;
    current = std::move(pending);
    pending.reset();
    writing = true;
    part_header = std::string("Content-Type: image/jpeg\r\nContent-Length: ") + std::to_string(current->size()) +
                  "\r\nX-Tessera-Frame: " + std::to_string(pending_frame) + "\r\n\r\n";
    static const std::string part_end = std::string("\r\n--") + kBoundary + "\r\n";
    std::vector<asio::const_buffer> bufs{asio::buffer(part_header), asio::buffer(*current), asio::buffer(part_end)};
    auto self = this->shared_from_this();
    asio::async_write(con->get_socket(), bufs, [self](const asio::error_code& ec, size_t) {
      self->writing = false;
      if (ec) { self->shutdown(); return; }
      self->write_next();
    });
  }
  // A viewer that goes away is noticed at once (its slot is free), not at the next frame.
  std::array<char, 512> discard;
  void watch_eof() {
    auto self = this->shared_from_this();
    con->get_socket().async_read_some(asio::buffer(discard), [self](const asio::error_code& ec, size_t) {
      if (ec) { self->shutdown(); return; }
      if (!self->dead) self->watch_eof();
    });
  }
  void start() {
    watch_eof();
    part_header = std::string("HTTP/1.1 200 OK\r\nContent-Type: multipart/x-mixed-replace; boundary=") + kBoundary +
                  "\r\nCache-Control: no-cache, no-store\r\nPragma: no-cache\r\nConnection: close\r\n" +
                  extra_headers + "\r\n--" +
                  kBoundary + "\r\n";
    writing = true;
    auto self = this->shared_from_this();
    asio::async_write(con->get_socket(), asio::buffer(part_header), [self](const asio::error_code& ec, size_t) {
      self->writing = false;
      if (ec) { self->shutdown(); return; }
      self->write_next();
    });
  }
  void shutdown() {
    if (dead) return;
    dead = true;
    if (live) --*live;
    close_socket(con);
  }
};

// A static file larger than kStreamAbove, written to its HTTP connection a chunk at a time
// from the file (the response deferred, as an MJPEG stream's), so that a request holds one
// chunk of memory however large the file, and the network thread reads no more than a chunk
// at once. Before, each request read the whole file into three copies (a 20 MB scene buffer
// cost 58 MB a request, 3.7 GB for 100 clients that did not read), and read it on the
// network thread, stalling every other client's frames meanwhile.
constexpr uint64_t kStreamAbove = 1u << 20;
constexpr size_t kStreamChunk = 256u << 10;
template <class Config>
struct FileStream : std::enable_shared_from_this<FileStream<Config>> {
  typename websocketpp::server<Config>::connection_ptr con;
  std::atomic<size_t>* live = nullptr;  // the server's count of open file streams
  std::ifstream in;
  uint64_t left = 0;  // bytes still to send
  std::string header;
  std::vector<char> chunk;
  bool done = false;
  // A client that takes no chunk for kStreamIdle is dropped: it holds one of kMaxFileStreams.
  static constexpr std::chrono::seconds kStreamIdle{20};
  std::unique_ptr<asio::steady_timer> idle;

  void start() {
    idle = std::make_unique<asio::steady_timer>(con->get_raw_socket().get_executor());
    write(asio::buffer(header));
  }
  void write(asio::const_buffer b) {
    auto self = this->shared_from_this();
    idle->expires_after(kStreamIdle);
    idle->async_wait([self](const asio::error_code& ec) {
      if (!ec) self->finish();  // not cancelled: no progress for kStreamIdle
    });
    asio::async_write(con->get_socket(), b, [self](const asio::error_code& ec, size_t) {
      if (ec) { self->finish(); return; }
      self->next();
    });
  }
  void next() {
    if (done) return;
    if (left == 0) { finish(); return; }
    const size_t n = size_t(std::min<uint64_t>(left, kStreamChunk));
    chunk.resize(n);
    if (!in.read(chunk.data(), std::streamsize(n))) { finish(); return; }  // the file shrank: the client sees it short
    left -= n;
    write(asio::buffer(chunk));
  }
  void finish() {
    if (done) return;
    done = true;
    if (idle) idle->cancel();
    if (live) --*live;
    close_socket(con);
  }
};

// Why a request is not admitted: the HTTP status and a short body, or, for a browser refused
// for its access token, the WebSocket close code and reason it is closed with at once.
struct Refusal {
  websocketpp::http::status_code::value status = websocketpp::http::status_code::forbidden;
  std::string reason;       // the body (with a newline) or the close reason
  uint16_t close_code = 0;  // 0: answered with the HTTP status
};

// The access token's query parameter on /ws and /mjpeg/NAME (docs/protocol.md, "Access tokens").
constexpr const char* kTokenParam = "access_token";
// Application close code for a refused access token (4000-4999 are the application's; 4401
// mirrors HTTP's 401, as other WebSocket protocols do).
constexpr uint16_t kCloseBadToken = 4401;
// TCP_NOTSENT_LOWAT of WebSocket connections (see on_open): at 1 Mbit/s 32 KiB is 0.26 s of
// latency; at 1 Gbit/s the network thread has ~0.13 ms to refill it (it is woken at half).
constexpr int kNotSentLowat = 32 << 10;
// A connection stops reading while its session has more than this many messages, or bytes, of
// its client waiting in its mailbox, and reads on once they are down to the resume marks: a
// client that sends small valid messages faster than its session takes them grew the node by
// gigabytes (the hostile-client probe of 2026-11-30), and TCP now holds it back instead.
constexpr uint32_t kInboxPauseMessages = 256, kInboxResumeMessages = 64;
constexpr uint64_t kInboxPauseBytes = 64ull << 20, kInboxResumeBytes = 16ull << 20;

// Throws unless this kernel lets the node's TCP connections use congestion control `name`.
void check_congestion_control(const std::string& name) {
  const int fd = ::socket(AF_INET, SOCK_STREAM, 0);
  if (fd < 0) throw std::runtime_error("tessera.tcp-congestion: cannot make a socket to check it");
  const int r = ::setsockopt(fd, IPPROTO_TCP, TCP_CONGESTION, name.data(), socklen_t(name.size()));
  const int err = errno;
  ::close(fd);
  if (r == 0) return;
  std::string available;
  std::ifstream in("/proc/sys/net/ipv4/tcp_available_congestion_control");
  std::getline(in, available);
  throw std::runtime_error("tessera.tcp-congestion '" + name + "' cannot be used here (" + std::strerror(err) +
                           "; this kernel offers: " + (available.empty() ? "unknown" : available) + ")");
}

// The client's address (remote) or the address it connected to, as text ("" when the socket
// is gone).
template <class ConnectionPtr>
std::string socket_address(const ConnectionPtr& con, bool remote) {
  asio::error_code ec;
  auto& socket = con->get_raw_socket();
  auto ep = remote ? socket.remote_endpoint(ec) : socket.local_endpoint(ec);
  return ec ? "" : admission::plain_address(ep.address().to_string());
}
template <class ConnectionPtr>
std::string peer_address(const ConnectionPtr& con) { return socket_address(con, true); }
template <class ConnectionPtr>
std::string local_address(const ConnectionPtr& con) { return socket_address(con, false); }

}  // namespace

// What Server reads of its endpoint, whichever the config.
struct Server::Impl {
  virtual ~Impl() = default;
  virtual void start() = 0;
  virtual void stop() = 0;
  virtual bool reload_tls(std::string* error) = 0;
  std::atomic<uint16_t> bound_port{0};
  std::atomic<uint16_t> redirect_bound{0};  // the plain HTTP redirect's port (0: none)
  std::atomic<size_t> count{0};
  std::atomic<uint64_t> queued{0};    // sum of the connections' backlogs
  std::atomic<size_t> viewers{0};     // open MJPEG streams
};

namespace {

template <class Config>
struct Sink;

template <class Config>
struct Endpoint final : Server::Impl, std::enable_shared_from_this<Endpoint<Config>> {
  using WsServer = websocketpp::server<Config>;
  using connection_ptr = typename WsServer::connection_ptr;
  using message_ptr = typename WsServer::message_ptr;
  static constexpr bool kTls = std::is_same_v<Config, websocketpp::config::asio_tls>;

  using PlainServer = websocketpp::server<websocketpp::config::asio>;

  caf::actor_system& sys;
  std::shared_ptr<const NodeSettings> settings;
  ServerOptions opts;
  WsServer ws;
  // kTls: every connection's context (one per node), and the certificate its handshakes
  // present, which reload_tls replaces (tls::ServerContext).
  std::shared_ptr<asio::ssl::context> tls_context;
  std::unique_ptr<tls::ServerContext> tls_identity;
  std::mutex reload_mu;
  std::string hsts;  // kTls and hsts_max_age > 0: the Strict-Transport-Security value, else ""
  // kTls and http_redirect_port: plain HTTP redirected to https, on ws's io_service (declared
  // after ws: it goes first, while that io_service still exists).
  std::unique_ptr<PlainServer> redirect;
  std::thread thread;
  std::atomic<uint64_t> next_id{0};
  bool running = false;

  // What waits to be handed to websocketpp for one connection (see enqueue).
  struct Out {
    std::shared_ptr<const std::vector<uint8_t>> bytes;
    bool frame = false;
  };
  struct Conn {
    session_actor session;
    std::shared_ptr<Sink<Config>> sink;
    bool closing = false;   // closed by the node: no longer holds a client slot
    std::deque<Out> out;    // at most one frame, and the records after it (order kept)
    size_t out_bytes = 0;
    bool frame_waiting = false;
    size_t largest_frame = 0;
    uint64_t backlog = 0;   // out_bytes + websocketpp's queue, as last seen
    BudgetShare share;      // backlog, in the node's budget
    LinkMeter link;         // the link's throughput (the H.264 display adapts its bitrate to it)
    connection_ptr held;    // the connection while it does not read (Sink::paused)
    uint64_t pauses = 0, next_pause_log = 1;
  };
  // Touched only on the network thread.
  std::map<connection_hdl, std::shared_ptr<Conn>, std::owner_less<connection_hdl>> conns;
  std::unique_ptr<asio::steady_timer> poll;  // flushes waiting frames (websocketpp has no send-complete callback)
  bool poll_armed = false;
  std::set<std::string> tokens;
  std::map<std::string, std::vector<std::shared_ptr<MjpegStream<Config>>>> mjpeg;
  // A viewer that opens late starts with the session's last JPEG (and its frame number).
  std::map<std::string, std::pair<std::shared_ptr<const std::vector<uint8_t>>, uint32_t>> last_mjpeg;
  // Validated connections not yet opened, with their session tokens ("": none). A token counts
  // as taken from validation on: a second upgrade with the same token, written right behind the
  // first, was admitted too (both got 101).
  std::map<connection_hdl, std::string, std::owner_less<connection_hdl>> pending_opens;
  bool token_taken(const std::string& t) const {
    if (tokens.count(t)) return true;
    for (auto& [h, p] : pending_opens)
      if (p == t) return true;
    return false;
  }
  // Admission (net/admission.h): WebSocket connections per client address, counted from the
  // upgrade until they close, and each counted connection's address.
  admission::AddressCounter per_address;
  std::map<connection_hdl, std::string, std::owner_less<connection_hdl>> counted;
  // Browser connections refused for their access token: upgraded only to be closed with the
  // reason, since a page learns nothing of a refused upgrade (no status, no body).
  std::map<connection_hdl, Refusal, std::owner_less<connection_hdl>> refusing;

  Endpoint(caf::actor_system& s, std::shared_ptr<const NodeSettings> st, ServerOptions o)
      : sys(s), settings(std::move(st)), opts(std::move(o)), per_address(opts.max_connections_per_ip) {
    if (kTls && opts.hsts_max_age > 0) hsts = "max-age=" + std::to_string(opts.hsts_max_age);
  }

  void start() override;
  void stop() override;
  bool reload_tls(std::string* error) override;
  void start_redirect(const asio::ip::address& addr);
  void on_redirect_http(connection_hdl h);
  bool on_redirect_validate(connection_hdl h);
  // The host a redirect names when the request's Host header is missing or not a host: the
  // node's address, or the one the client connected to when the node listens on all of them.
  std::string fallback_host(const PlainServer::connection_ptr& con) const;

  void log(Event e) { node_log(*settings, std::move(e)); }
  void on_open(connection_hdl h);
  void on_close(connection_hdl h);
  bool on_validate(connection_hdl h);
  std::optional<Refusal> check_origin(const connection_ptr& con, const char* endpoint, const std::string& address);
  std::optional<Refusal> check_token(const connection_ptr& con, const char* endpoint, const std::string& address);
  std::optional<Refusal> check_capacity(const std::string& address);
  void release_address(connection_hdl h);
  void on_message(connection_hdl h, message_ptr msg);
  void resume(connection_hdl h);  // reads the client's messages again (Sink::consumed)
  void post_resume(connection_hdl h);
  bool on_ping(connection_hdl h);
  void on_fail(connection_hdl h);
  void on_http(connection_hdl h);
  // Queues a message for the connection; false when the connection is gone or closing.
  bool enqueue(connection_hdl h, std::shared_ptr<const std::vector<uint8_t>> msg, bool frame);
  void flush(connection_hdl h, Conn& c);
  void arm_poll();
  void close_conn(connection_hdl h, Conn& c, websocketpp::close::status::value code, const std::string& reason);
  std::atomic<size_t> open_conns{0};  // including those being closed
  std::atomic<size_t> file_streams{0};  // FileStreams writing
  static constexpr size_t kMaxFileStreams = 64;
  void recount() {
    size_t n = 0;
    for (auto& [h, c] : conns) n += !c->closing;
    count = n;
    open_conns = conns.size();
  }
  size_t live_viewers(const std::string& token) {
    auto it = mjpeg.find(token);
    if (it == mjpeg.end()) return 0;
    auto& v = it->second;
    v.erase(std::remove_if(v.begin(), v.end(), [](auto& s) { return s->dead; }), v.end());
    return v.size();
  }
  void end_mjpeg(const std::string& token) {
    last_mjpeg.erase(token);
    auto it = mjpeg.find(token);
    if (it == mjpeg.end()) return;
    for (auto& s : it->second) s->shutdown();
    mjpeg.erase(it);
  }
};

// The session's way back to its client; posts everything onto the network thread.
template <class Config>
struct Sink : ClientSink {
  using Impl = Endpoint<Config>;
  std::weak_ptr<Impl> impl;
  connection_hdl hdl;
  std::string tok;
  std::atomic<bool> open{true};

  void post(std::function<void(Impl&)> f) {
    auto i = impl.lock();
    if (!i || !open) return;
    std::weak_ptr<Impl> w = i;
    i->ws.get_io_service().post([w, f = std::move(f)] {
      if (auto i = w.lock()) f(*i);
    });
  }
  std::atomic<uint32_t> dropped{0};  // frames replaced before the client took them
  void send(std::vector<uint8_t> message) override {
    auto p = std::make_shared<const std::vector<uint8_t>>(std::move(message));
    auto h = hdl;
    post([h, p](Impl& i) { i.enqueue(h, p, false); });
  }
  // Frames posted and not yet written or replaced (frames_unsent); shared with the posted work.
  std::shared_ptr<std::atomic<uint32_t>> unsent = std::make_shared<std::atomic<uint32_t>>(0);
  std::function<void()> frame_gone;  // on_frame_gone's callback (set before the first frame)
  void on_frame_gone(std::function<void()> f) override { frame_gone = std::move(f); }
  // A frame left: it was written, replaced, or its connection is gone.
  static void gone(const std::shared_ptr<std::atomic<uint32_t>>& u, const std::function<void()>& f) {
    --*u;
    if (f) f();
  }
  void send_frame(std::vector<uint8_t> message) override {
    auto p = std::make_shared<const std::vector<uint8_t>>(std::move(message));
    auto h = hdl;
    auto u = unsent;
    ++*u;
    auto i = impl.lock();
    if (!i || !open) {
      --*u;
      return;
    }
    std::weak_ptr<Impl> w = i;
    i->ws.get_io_service().post([w, h, p, u, f = frame_gone] {
      auto i = w.lock();
      if (!i || !i->enqueue(h, p, true)) gone(u, f);  // the connection is gone: nothing waits
    });
  }
  uint32_t frames_dropped() const override { return dropped; }
  uint32_t frames_unsent() const override { return *unsent; }
  // The connection's LinkMeter, published by the network thread after each sample.
  std::atomic<uint32_t> link{0};
  std::atomic<int64_t> link_ns{0};
  std::atomic<uint32_t> waited{0};  // frames_waited()
  uint32_t frames_waited() const override { return waited; }
  std::atomic<int64_t> saturated_ns{0};  // the end of the link's last saturated window
  bool link_saturated() const override {
    const int64_t s = saturated_ns.load();
    return s > 0 && steady_ns() - s <= LinkMeter::kSaturatedNs;
  }
  uint32_t link_kbps() const override {
    return steady_ns() - link_ns.load() > LinkMeter::kStaleNs ? 0 : link.load();
  }
  void send_mjpeg(std::shared_ptr<const std::vector<uint8_t>> jpeg, uint32_t frame) override {
    auto t = tok;
    post([t, jpeg, frame](Impl& i) {
      if (!i.tokens.count(t)) return;  // the session's client has gone
      i.last_mjpeg[t] = {jpeg, frame};
      auto it = i.mjpeg.find(t);
      if (it == i.mjpeg.end()) return;
      auto& v = it->second;
      v.erase(std::remove_if(v.begin(), v.end(), [](auto& s) { return s->dead; }), v.end());
      for (auto& s : v) s->push(jpeg, frame);
    });
  }
  void close(const std::string& reason) override {
    auto h = hdl;
    std::string r = reason.substr(0, 120);  // close reasons are limited to 123 bytes
    post([h, r](Impl& i) {
      auto it = i.conns.find(h);
      if (it != i.conns.end()) i.close_conn(h, *it->second, websocketpp::close::status::policy_violation, r);
    });
    open = false;
  }
  std::string token() const override { return tok; }
  std::string origin;
  std::string node_origin() const override { return origin; }
  // The client's messages in the session's mailbox (on_message adds, consumed takes away), and
  // whether the connection has stopped reading for them (set and cleared on the network thread).
  std::atomic<uint64_t> inbox_bytes{0};
  std::atomic<uint32_t> inbox_messages{0};
  std::atomic<bool> paused{false};
  static bool below_resume(uint32_t messages, uint64_t bytes) {
    return messages <= kInboxResumeMessages && bytes <= kInboxResumeBytes;
  }
  void consumed(size_t bytes) override {
    const uint64_t b = inbox_bytes.fetch_sub(bytes) - bytes;
    const uint32_t m = inbox_messages.fetch_sub(1) - 1;
    if (paused.load() && below_resume(m, b)) {
      auto h = hdl;
      post([h](Impl& i) { i.resume(h); });
    }
  }
};

// A client that does not read must not grow the node: websocketpp queues every send without
// bound and says nothing when one has been written, so frames are handed to it only while
// its queue is empty (get_buffered_amount() == 0: what it holds is being written). Meanwhile
// the newest frame waits here and replaces an older waiting one (counted as dropped); the
// records sent after a waiting frame wait behind it, so the client sees them in order. A
// client costs at most three frames: one being written, one queued behind it, one waiting.
template <class Config>
bool Endpoint<Config>::enqueue(connection_hdl h, std::shared_ptr<const std::vector<uint8_t>> msg, bool frame) {
  auto it = conns.find(h);
  if (it == conns.end() || it->second->closing) return false;
  Conn& c = *it->second;
  if (frame) {
    if (c.frame_waiting) flush(h, c);  // it may go now, rather than be replaced
    if (c.closing) return false;
    if (c.frame_waiting) {
      for (auto o = c.out.begin(); o != c.out.end(); ++o)
        if (o->frame) {
          c.out_bytes -= o->bytes->size();
          c.out.erase(o);
          break;
        }
      c.sink->dropped++;
      Sink<Config>::gone(c.sink->unsent, c.sink->frame_gone);  // the replaced frame will not be written
    }
    c.frame_waiting = true;
    c.largest_frame = std::max(c.largest_frame, msg->size());
  }
  c.out_bytes += msg->size();
  c.out.push_back(Out{std::move(msg), frame});
  flush(h, c);
  if (frame && c.frame_waiting) c.sink->waited++;  // it waits for the link
  return true;
}

template <class Config>
void Endpoint<Config>::flush(connection_hdl h, Conn& c) {
  websocketpp::lib::error_code ec;
  auto con = ws.get_con_from_hdl(h, ec);
  if (ec || c.closing) return;
  while (!c.out.empty()) {
    Out& o = c.out.front();
    if (o.frame && con->get_buffered_amount() > 0) break;
    con->send(o.bytes->data(), o.bytes->size(), websocketpp::frame::opcode::binary);  // copies the bytes
    c.out_bytes -= o.bytes->size();
    if (o.frame) {
      c.frame_waiting = false;
      Sink<Config>::gone(c.sink->unsent, c.sink->frame_gone);
    }
    c.out.pop_front();
  }
  // The link's throughput, while it holds bytes back (net/link_meter.h).
  const TcpFigures tcp = tcp_figures(con->get_raw_socket().native_handle());
  const int64_t now = steady_ns();
  if (tcp.ok && c.link.look(now, tcp.acked, tcp.notsent)) {
    c.sink->link = c.link.kbps(now);
    c.sink->link_ns = now;
    c.sink->saturated_ns = now;
  }
  const uint64_t backlog = c.out_bytes + con->get_buffered_amount();
  queued += backlog - c.backlog;  // unsigned wrap-around adds the (possibly negative) difference
  c.backlog = backlog;
  c.share.set(backlog);
  // Records other than frames are not replaced: a client that lets them pile up (it sends
  // malformed messages and never reads the errors) is closed.
  const uint64_t cap = std::max<uint64_t>(8u << 20, 3 * uint64_t(c.largest_frame));
  if (backlog > cap) {
    log(Event(Ev::closed_slow_client, true).with("backlog", backlog));
    close_conn(h, c, websocketpp::close::status::policy_violation, "client is not reading");
    return;
  }
  if (backlog > 0 || c.link.watching()) arm_poll();
}

template <class Config>
void Endpoint<Config>::arm_poll() {
  if (poll_armed || !poll) return;
  poll_armed = true;
  poll->expires_after(std::chrono::milliseconds(2));
  poll->async_wait([this](const asio::error_code& ec) {
    poll_armed = false;
    if (ec) return;
    // flush() may close (and not erase) a connection: iterate over a copy of the handles.
    std::vector<std::pair<connection_hdl, std::shared_ptr<Conn>>> busy;
    for (auto& [h, c] : conns)
      if ((c->backlog > 0 || c->link.watching()) && !c->closing) busy.emplace_back(h, c);
    for (auto& [h, c] : busy) flush(h, *c);
  });
}

template <class Config>
void Endpoint<Config>::close_conn(connection_hdl h, Conn& c, websocketpp::close::status::value code,
                              const std::string& reason) {
  if (c.closing) return;
  // The records already queued (the fatal error record) go out before the close frame; a
  // waiting frame does not.
  websocketpp::lib::error_code ec;
  for (auto& o : c.out)
    if (!o.frame) ws.send(h, o.bytes->data(), o.bytes->size(), websocketpp::frame::opcode::binary, ec);
  c.out.clear();
  c.out_bytes = 0;
  c.frame_waiting = false;
  c.closing = true;
  queued -= c.backlog;
  c.backlog = 0;
  c.share.set(0);
  c.sink->open = false;
  caf::anon_send_exit(c.session, caf::exit_reason::user_shutdown);  // no-op when it ended itself
  recount();
  ws.close(h, code, reason, ec);
  if (c.sink->paused) post_resume(h);  // reading again, so that the client's close frame is read
}

// A page's origin is checked first: a foreign page gets HTTP 403 and never a WebSocket. Then
// the client's address (HTTP 429), its access token (HTTP 401; a browser's upgrade completes
// and closes at once with 4401 and the reason, which is all a page can read), the node's
// capacity (503) and the session name (400). Every refusal logs one `rejected` event, never
// the token or the query string it came in.
template <class Config>
bool Endpoint<Config>::on_validate(connection_hdl h) {
  auto con = ws.get_con_from_hdl(h);
  if (!hsts.empty()) con->replace_header("Strict-Transport-Security", hsts);  // the 101 and every refusal
  const std::string target = con->get_resource();
  if (http::target_path(target) != "/ws") {
    con->set_status(websocketpp::http::status_code::not_found);
    con->set_body("WebSocket endpoint is /ws\n");
    return false;
  }
  const std::string address = peer_address(con);
  std::optional<Refusal> refusal = check_origin(con, "/ws", address);
  if (!refusal) refusal = check_capacity(address);
  if (refusal) {
    con->set_status(refusal->status);
    con->set_body(refusal->reason + "\n");
    if (refusal->status == websocketpp::http::status_code::too_many_requests) con->replace_header("Retry-After", "5");
    return false;
  }
  if (auto bad_token = check_token(con, "/ws", address)) {
    if (con->get_request_header("Origin").empty()) {  // not a browser: the plain HTTP answer
      con->set_status(bad_token->status);
      con->set_body(bad_token->reason + "\n");
      con->replace_header("WWW-Authenticate", "Bearer realm=\"tessera\"");
      return false;
    }
    // Counted per address until it has closed, so refused browsers cannot pile up either.
    per_address.try_add(address);
    counted[h] = address;
    refusing[h] = *bad_token;
    return true;
  }
  if (count + pending_opens.size() >= opts.max_clients) {
    con->set_status(websocketpp::http::status_code::service_unavailable);
    con->set_body("server full: " + std::to_string(opts.max_clients) + " clients\n");
    log(Event(Ev::rejected, "server full").with("max_clients", opts.max_clients));
    return false;
  }
  std::string token = http::query_param(target, "session");
  if (!token.empty() && (!http::valid_token(token) || token_taken(token))) {
    const bool valid = http::valid_token(token);
    con->set_status(websocketpp::http::status_code::bad_request);
    con->set_body(valid ? "session token in use\n" : "bad session token (8..64 of A-Z a-z 0-9 _ -)\n");
    return false;
  }
  per_address.try_add(address);
  counted[h] = address;
  pending_opens[h] = token;
  return true;
}

template <class Config>
std::optional<Refusal> Endpoint<Config>::check_origin(const connection_ptr& con, const char* endpoint,
                                                      const std::string& address) {
  const std::string origin = con->get_request_header("Origin");
  if (opts.origins.allows(origin, local_address(con), bound_port)) return std::nullopt;
  const char* reason = origin.empty() ? "origin required" : "origin not allowed";
  log(Event(Ev::rejected, reason).with("endpoint", endpoint).with("address", address).with("origin", origin.substr(0, 256)));
  return Refusal{websocketpp::http::status_code::forbidden, reason};
}

template <class Config>
std::optional<Refusal> Endpoint<Config>::check_token(const connection_ptr& con, const char* endpoint,
                                                     const std::string& address) {
  using admission::Verdict;
  const admission::TokenCheck c =
      opts.tokens.check(http::query_param(con->get_resource(), kTokenParam), int64_t(std::time(nullptr)));
  if (c.verdict == Verdict::ok) return std::nullopt;
  const char* reason = c.verdict == Verdict::missing   ? "access token required"
                       : c.verdict == Verdict::expired ? "access token expired"
                                                       : "access token invalid";
  Event e(Ev::rejected, reason);
  e.with("endpoint", endpoint).with("address", address);
  if (c.verdict != Verdict::missing && c.verdict != Verdict::expired) e.with("why", admission::verdict_name(c.verdict));
  if (c.verdict == Verdict::expired) e.with("subject", c.subject).with("expired_at", c.expiry);
  log(std::move(e));
  return Refusal{websocketpp::http::status_code::unauthorized, reason, kCloseBadToken};
}

template <class Config>
std::optional<Refusal> Endpoint<Config>::check_capacity(const std::string& address) {
  if (opts.max_connections_per_ip == 0 || per_address.count(address) < opts.max_connections_per_ip) return std::nullopt;
  log(Event(Ev::rejected, "too many connections from this address")
          .with("address", address)
          .with("max_connections_per_ip", opts.max_connections_per_ip));
  return Refusal{websocketpp::http::status_code::too_many_requests,
                 "too many connections from this address: " + std::to_string(opts.max_connections_per_ip) +
                     " (max-connections-per-ip)"};
}

template <class Config>
void Endpoint<Config>::release_address(connection_hdl h) {
  auto it = counted.find(h);
  if (it == counted.end()) return;
  per_address.remove(it->second);
  counted.erase(it);
}

template <class Config>
void Endpoint<Config>::on_open(connection_hdl h) {
  pending_opens.erase(h);
  if (auto r = refusing.find(h); r != refusing.end()) {  // no session: closed with the reason
    websocketpp::lib::error_code ec;
    ws.close(h, r->second.close_code, r->second.reason, ec);
    return;
  }
  auto con = ws.get_con_from_hdl(h);
  // The kernel keeps at most kNotSentLowat bytes that the link has not yet taken (beside those
  // in flight): a slow link's frames wait in the node, where the newest replaces older ones
  // and the H.264 display sees the link (net/link_meter.h), not in a socket buffer of
  // megabytes that would only add latency.
  const int lowat = kNotSentLowat;
  ::setsockopt(con->get_raw_socket().native_handle(), IPPROTO_TCP, TCP_NOTSENT_LOWAT, &lowat, sizeof lowat);
  auto sink = std::make_shared<Sink<Config>>();
  sink->impl = this->shared_from_this();
  sink->hdl = h;
  sink->tok = http::query_param(con->get_resource(), "session");
  const std::string host = con->get_request_header("Host");
  if (!host.empty()) sink->origin = std::string(opts.tls() ? "https://" : "http://") + host;
  if (!sink->tok.empty()) tokens.insert(sink->tok);
  uint64_t id = ++next_id;
  auto c = std::make_shared<Conn>();
  c->session = spawn_session(sys, sink, settings, id);
  c->sink = sink;
  c->share.attach(settings->budget);
  conns[h] = std::move(c);
  recount();
}

template <class Config>
void Endpoint<Config>::on_close(connection_hdl h) {
  pending_opens.erase(h);
  refusing.erase(h);
  release_address(h);
  auto it = conns.find(h);
  if (it == conns.end()) return;
  Conn& c = *it->second;
  c.sink->open = false;
  caf::anon_send_exit(c.session, caf::exit_reason::user_shutdown);
  if (!c.sink->tok.empty()) {
    tokens.erase(c.sink->tok);
    end_mjpeg(c.sink->tok);
  }
  queued -= c.backlog;
  conns.erase(it);
  recount();
}

// A connection that ended before it was a WebSocket or an HTTP exchange. With TLS, one whose
// handshake failed (a plain HTTP or WebSocket client on the HTTPS port, an old protocol
// version, a client that does not trust the certificate) is a refusal, logged as such.
template <class Config>
void Endpoint<Config>::on_fail(connection_hdl h) {
  if constexpr (kTls) {
    websocketpp::lib::error_code ec;
    auto con = ws.get_con_from_hdl(h, ec);
    namespace sock = websocketpp::transport::asio::socket;
    if (!ec && con->get_ec() == sock::make_error_code(sock::error::tls_handshake_failed))
      log(Event(Ev::rejected, "TLS handshake failed").with("address", peer_address(con)));
  }
  on_close(h);
}

template <class Config>
void Endpoint<Config>::on_message(connection_hdl h, message_ptr msg) {
  auto it = conns.find(h);
  if (it == conns.end() || it->second->closing) return;
  Conn& c = *it->second;
  const std::string& p = msg->get_payload();
  Sink<Config>& sink = *c.sink;
  sink.inbox_messages++;
  sink.inbox_bytes += p.size();
  // Text messages go to the decoder too: it answers them with a protocol error (bad magic).
  caf::anon_send(c.session, client_atom::value, std::vector<uint8_t>(p.begin(), p.end()));
  if (sink.paused || (sink.inbox_messages <= kInboxPauseMessages && sink.inbox_bytes <= kInboxPauseBytes)) return;
  websocketpp::lib::error_code ec;
  auto con = ws.get_con_from_hdl(h, ec);
  if (ec) return;
  // At once, not through pause_reading(), which posts the pause: a read could be issued before
  // it took effect, and the resume would then start a second read beside it (the connection's
  // bytes were read twice and it broke). This handler runs inside the connection's read
  // handler, which issues no further read once the flag is down.
  con->handle_pause_reading();
  sink.paused = true;
  c.held = con;  // with no read in flight nothing else holds it: websocketpp would free it
  // Logged the 1st, 10th, 100th... time for a connection (a flood pauses it thousands of times).
  if (++c.pauses == c.next_pause_log) {
    c.next_pause_log *= 10;
    log(Event(Ev::paused_reading, true).with("times", c.pauses)
            .with("waiting_messages", uint64_t(sink.inbox_messages.load()))
            .with("waiting_bytes", sink.inbox_bytes.load()));
  }
  // The session may have taken them all before `paused` was set (it posts a resume only when
  // it sees it set).
  if (Sink<Config>::below_resume(sink.inbox_messages, sink.inbox_bytes)) post_resume(h);
}

// Resumes in a handler of its own: inside websocketpp's read handler (on_message, on_ping) a
// resume would issue a read, and the handler another one when it returns, two reads into one
// buffer.
template <class Config>
void Endpoint<Config>::post_resume(connection_hdl h) {
  std::weak_ptr<Endpoint> w = this->shared_from_this();
  ws.get_io_service().post([w, h] {
    if (auto i = w.lock()) i->resume(h);
  });
}

template <class Config>
void Endpoint<Config>::resume(connection_hdl h) {
  auto it = conns.find(h);
  if (it == conns.end()) return;
  Sink<Config>& sink = *it->second->sink;
  // A closing connection reads again whatever waits (the client's close frame must be read).
  if (!sink.paused || (!it->second->closing && !Sink<Config>::below_resume(sink.inbox_messages, sink.inbox_bytes)))
    return;
  websocketpp::lib::error_code ec;
  auto con = ws.get_con_from_hdl(h, ec);
  if (ec) return;
  con->handle_resume_reading();  // on this thread, as the pause: exactly one read is issued
  sink.paused = false;
  it->second->held.reset();
}

// A ping's pong is queued by websocketpp itself, beside the node's messages: a client that
// pings without reading is held to the same backlog as one that does not read its frames
// (flush closes it above the cap). Before, nothing looked at the backlog while the node had
// nothing of its own to send, and a ping flood grew the node by 150 MB/s.
template <class Config>
bool Endpoint<Config>::on_ping(connection_hdl h) {
  auto it = conns.find(h);
  if (it == conns.end()) return true;  // a refused browser's connection, closing at once
  Conn& c = *it->second;
  if (c.closing) return false;
  flush(h, c);
  if (!c.closing) arm_poll();  // the pong is queued after this returns: looked at again soon
  return !c.closing;
}

// Sets a response's status, headers and body. HEAD gets the same headers (Content-Length of
// the body a GET would get) and no body.
template <class ConnectionPtr>
void respond(const ConnectionPtr& con, bool head, websocketpp::http::status_code::value status,
             const std::string& body, const char* content_type = "text/plain; charset=utf-8") {
  con->set_status(status);
  con->replace_header("Content-Type", content_type);
  con->replace_header("X-Content-Type-Options", "nosniff");
  con->set_body(head ? std::string() : body);
  con->replace_header("Content-Length", std::to_string(body.size()));
}

template <class Config>
void Endpoint<Config>::on_http(connection_hdl h) {
  namespace sc = websocketpp::http::status_code;
  auto con = ws.get_con_from_hdl(h);
  if (!hsts.empty()) con->replace_header("Strict-Transport-Security", hsts);
  const std::string target = con->get_resource();
  const std::string path = http::target_path(target);
  const std::string& method = con->get_request().get_method();
  if (method != "GET" && method != "HEAD") {
    respond(con, false, sc::method_not_allowed, "method not allowed: GET and HEAD only\n");
    con->replace_header("Allow", "GET, HEAD");
    return;
  }
  const bool head = method == "HEAD";
  if (path.rfind("/mjpeg/", 0) == 0) {
    // Admission as on /ws: an <img> sends no Origin header, so the allow-list applies only to
    // requests that carry one (a foreign page's fetch), the access token to every request.
    const std::string address = peer_address(con);
    std::optional<Refusal> refusal;
    if (!con->get_request_header("Origin").empty()) refusal = check_origin(con, "/mjpeg/", address);
    if (!refusal) refusal = check_token(con, "/mjpeg/", address);
    if (refusal) {
      respond(con, head, refusal->status, refusal->reason + "\n");
      if (refusal->status == sc::unauthorized) con->replace_header("WWW-Authenticate", "Bearer realm=\"tessera\"");
      return;
    }
    std::string token = path.substr(7);
    if (!tokens.count(token)) {
      respond(con, head, sc::not_found, "no session with this token\n");
      return;
    }
    const size_t of_session = live_viewers(token), all = viewers;  // viewers: kept by start/shutdown
    if (of_session >= opts.max_mjpeg_per_session || all >= opts.max_mjpeg_viewers) {
      const bool session_full = of_session >= opts.max_mjpeg_per_session;
      respond(con, head, sc::service_unavailable,
              session_full ? "too many MJPEG viewers of this session: " + std::to_string(opts.max_mjpeg_per_session) +
                                 " (max-mjpeg-per-session)\n"
                           : "too many MJPEG viewers on this node: " + std::to_string(opts.max_mjpeg_viewers) +
                                 " (max-mjpeg-viewers)\n");
      con->replace_header("Retry-After", "5");
      if (!head)
        log(Event(Ev::rejected, "mjpeg viewers").with("limit", session_full ? "max-mjpeg-per-session" : "max-mjpeg-viewers"));
      return;
    }
    if (head) {  // the headers of the stream, no stream
      respond(con, true, sc::ok, "", "multipart/x-mixed-replace; boundary=tesseraframe");
      con->remove_header("Content-Length");
      return;
    }
    con->defer_http_response();
    auto s = std::make_shared<MjpegStream<Config>>();
    s->con = con;
    if (!hsts.empty()) s->extra_headers = "Strict-Transport-Security: " + hsts + "\r\n";
    s->live = &viewers;
    ++viewers;
    mjpeg[token].push_back(s);
    s->start();
    if (auto last = last_mjpeg.find(token); last != last_mjpeg.end()) s->push(last->second.first, last->second.second);
    return;
  }
  if (path == "/ws") {
    respond(con, head, sc::upgrade_required, "WebSocket endpoint\n");
    return;
  }
  std::optional<std::string> file;
  if (path == "/") {
    file = http::resolve_public(opts.web_root, "/index.html", opts.web_public);
    if (!file) file = http::resolve_public(opts.web_root, "/demo/index.html", opts.web_public);
  } else if (target.rfind("/scenes/", 0) == 0) {
    file = http::resolve_static(opts.scenes_root, target.substr(7));
  } else {
    file = http::resolve_public(opts.web_root, target, opts.web_public);
  }
  std::ifstream in;
  if (file) in.open(*file, std::ios::binary);
  if (!file || !in || !in.seekg(0, std::ios::end)) {
    respond(con, head, sc::not_found, "not found\n");
    return;
  }
  const std::streamoff end = in.tellg();
  if (end < 0) {
    respond(con, head, sc::not_found, "not found\n");
    return;
  }
  const uint64_t size = uint64_t(end);
  http::ByteRange range;
  // A Range on HEAD is ignored (RFC 9110 14.2): the headers of the whole file.
  const http::RangeKind kind =
      head ? http::RangeKind::full : http::parse_range(con->get_request_header("Range"), size, range);
  const char* type = http::mime_type(*file);
  if (kind == http::RangeKind::unsatisfiable) {
    respond(con, false, sc::request_range_not_satisfiable, "range not satisfiable\n");
    con->replace_header("Content-Range", "bytes */" + std::to_string(size));
    con->replace_header("Accept-Ranges", "bytes");
    return;
  }
  const uint64_t first = kind == http::RangeKind::partial ? range.first : 0;
  const uint64_t length = kind == http::RangeKind::partial ? range.last - range.first + 1 : size;
  const auto status = kind == http::RangeKind::partial ? sc::partial_content : sc::ok;
  const std::string content_range = "bytes " + std::to_string(first) + "-" + std::to_string(first + length - 1) + "/" +
                                    std::to_string(size);
  if (head || length <= kStreamAbove) {  // read at once (HEAD: only its size)
    std::string bytes;
    if (!head) {
      bytes.resize(size_t(length));
      if (!in.seekg(std::streamoff(first)) || !in.read(bytes.data(), std::streamsize(length))) {
        respond(con, head, sc::internal_server_error, "cannot read the file\n");
        return;
      }
    }
    respond(con, head, status, bytes, type);
    if (head) con->replace_header("Content-Length", std::to_string(length));
    if (kind == http::RangeKind::partial) con->replace_header("Content-Range", content_range);
    con->replace_header("Accept-Ranges", "bytes");
    con->replace_header("Cache-Control", "no-cache");
    return;
  }
  if (file_streams >= kMaxFileStreams) {
    respond(con, false, sc::service_unavailable,
            "busy: " + std::to_string(kMaxFileStreams) + " large files are being sent; try again\n");
    con->replace_header("Retry-After", "1");
    return;
  }
  if (!in.seekg(std::streamoff(first))) {
    respond(con, false, sc::internal_server_error, "cannot read the file\n");
    return;
  }
  con->defer_http_response();
  auto f = std::make_shared<FileStream<Config>>();
  f->con = con;
  f->in = std::move(in);
  f->left = length;
  f->live = &file_streams;
  ++file_streams;
  f->header = std::string("HTTP/1.1 ") + (status == sc::ok ? "200 OK" : "206 Partial Content") +
              "\r\nContent-Type: " + type + "\r\nContent-Length: " + std::to_string(length) +
              "\r\nAccept-Ranges: bytes\r\nCache-Control: no-cache\r\nX-Content-Type-Options: nosniff\r\n" +
              (kind == http::RangeKind::partial ? "Content-Range: " + content_range + "\r\n" : std::string()) +
              (hsts.empty() ? std::string() : "Strict-Transport-Security: " + hsts + "\r\n") + "Connection: close\r\n\r\n";
  f->start();
}

// The `tls_certificate` event of a certificate the port presents from now on.
Event certificate_event(const char* what, const std::string& cert_file, const tls::CertInfo& info) {
  Event e(Ev::tls_certificate, what);
  e.with("cert", cert_file).with("subject", info.subject).with("not_after", info.not_after).with("sha256", info.sha256);
  if (info.expires > 0 && info.expires < int64_t(std::time(nullptr)))
    e.with("warning", "the certificate expired at " + info.not_after + ": browsers refuse it");
  return e;
}

template <class Config>
void Endpoint<Config>::start() {
  Endpoint& i = *this;
  if constexpr (kTls) {  // before anything binds: a bad certificate or key ends the start
    std::lock_guard<std::mutex> l(reload_mu);
    tls_identity = std::make_unique<tls::ServerContext>(opts.tls_cert, opts.tls_key);
    SSL_CTX_up_ref(tls_identity->native());  // asio's context holds a reference of its own
    tls_context = std::make_shared<asio::ssl::context>(tls_identity->native());
    i.ws.set_tls_init_handler([ctx = tls_context](connection_hdl) { return ctx; });
  } else if (opts.http_redirect_port) {
    throw std::runtime_error("tessera.http-redirect-port needs TLS (tessera.tls-cert and tessera.tls-key): it "
                             "redirects plain HTTP to https://");
  }
  i.ws.clear_access_channels(websocketpp::log::alevel::all);
  i.ws.clear_error_channels(websocketpp::log::elevel::all);
  i.ws.init_asio();
  i.ws.set_reuse_addr(true);
  i.ws.set_user_agent("");  // no Server header
  i.poll = std::make_unique<asio::steady_timer>(i.ws.get_io_service());
  i.ws.set_max_message_size(i.settings->limits.max_message_bytes);
  i.ws.set_max_http_body_size(64 * 1024);
  if (!i.opts.tcp_congestion.empty()) check_congestion_control(i.opts.tcp_congestion);
  i.ws.set_tcp_post_init_handler([&i](connection_hdl h) {
    asio::error_code ec;
    auto& socket = i.ws.get_con_from_hdl(h)->get_raw_socket();
    socket.set_option(asio::ip::tcp::no_delay(true), ec);
    const std::string& cc = i.opts.tcp_congestion;
    if (!cc.empty()) ::setsockopt(socket.native_handle(), IPPROTO_TCP, TCP_CONGESTION, cc.data(), socklen_t(cc.size()));
  });
  i.ws.set_validate_handler([&i](connection_hdl h) { return i.on_validate(h); });
  i.ws.set_open_handler([&i](connection_hdl h) { i.on_open(h); });
  i.ws.set_close_handler([&i](connection_hdl h) { i.on_close(h); });
  i.ws.set_fail_handler([&i](connection_hdl h) { i.on_fail(h); });
  i.ws.set_message_handler([&i](connection_hdl h, message_ptr m) { i.on_message(h, m); });
  i.ws.set_ping_handler([&i](connection_hdl h, std::string) { return i.on_ping(h); });
  i.ws.set_http_handler([&i](connection_hdl h) { i.on_http(h); });
  asio::error_code ec;
  auto addr = asio::ip::make_address(i.opts.host, ec);
  if (ec) throw std::runtime_error("bad listen address '" + i.opts.host + "': " + ec.message());
  i.ws.listen(asio::ip::tcp::endpoint(addr, i.opts.port), ec);
  if (ec) throw std::runtime_error("cannot listen on " + i.opts.host + ":" + std::to_string(i.opts.port) + ": " + ec.message());
  i.ws.start_accept(ec);
  if (ec) throw std::runtime_error("cannot accept: " + ec.message());
  i.bound_port = i.ws.get_local_endpoint(ec).port();
  if constexpr (kTls)
    if (i.opts.http_redirect_port) i.start_redirect(addr);
  i.running = true;
  i.thread = std::thread([&i] {
    try {
      i.ws.run();
    } catch (const std::exception& e) {
      i.log(Event(Ev::network_thread_error, e.what()));
    }
  });
  if constexpr (kTls) i.log(certificate_event("loaded", i.opts.tls_cert, i.tls_identity->current()));
}

template <class Config>
bool Endpoint<Config>::reload_tls(std::string* error) {
  std::lock_guard<std::mutex> l(reload_mu);
  std::string why;
  if constexpr (kTls) {
    if (!tls_identity) {
      why = "the server has not started";
    } else {
      try {
        log(certificate_event("reloaded", opts.tls_cert, tls_identity->reload(opts.tls_cert, opts.tls_key)));
        return true;
      } catch (const std::exception& e) {
        why = e.what();  // names the file and OpenSSL's reason, never a key's content
      }
    }
    const tls::CertInfo kept = tls_identity ? tls_identity->current() : tls::CertInfo{};
    log(Event(Ev::tls_certificate, "reload_failed")
            .with("error", why)
            .with("serving", kept.subject)
            .with("serving_sha256", kept.sha256)
            .with("serving_not_after", kept.not_after));
  } else {
    why = "no TLS on this node (tessera.tls-cert and tessera.tls-key are not set)";
    log(Event(Ev::tls_certificate, "reload_failed").with("error", why));
  }
  if (error) *error = why;
  return false;
}

// The plain HTTP listener of ServerOptions::http_redirect_port: websocketpp's plain config on the
// TLS endpoint's io_service (its network thread), bound to the same address.
template <class Config>
void Endpoint<Config>::start_redirect(const asio::ip::address& addr) {
  redirect = std::make_unique<PlainServer>();
  PlainServer& r = *redirect;
  r.clear_access_channels(websocketpp::log::alevel::all);
  r.clear_error_channels(websocketpp::log::elevel::all);
  r.init_asio(&ws.get_io_service());
  r.set_reuse_addr(true);
  r.set_user_agent("");
  r.set_max_http_body_size(4096);
  r.set_http_handler([this](connection_hdl h) { on_redirect_http(h); });
  r.set_validate_handler([this](connection_hdl h) { return on_redirect_validate(h); });
  asio::error_code ec;
  r.listen(asio::ip::tcp::endpoint(addr, *opts.http_redirect_port), ec);
  if (ec)
    throw std::runtime_error("cannot listen on " + opts.host + ":" + std::to_string(*opts.http_redirect_port) +
                             " (tessera.http-redirect-port): " + ec.message());
  r.start_accept(ec);
  if (ec) throw std::runtime_error("cannot accept on the redirect port: " + ec.message());
  redirect_bound = r.get_local_endpoint(ec).port();
}

template <class Config>
std::string Endpoint<Config>::fallback_host(const PlainServer::connection_ptr& con) const {
  asio::error_code ec;
  auto host = asio::ip::make_address(opts.host, ec);
  if (ec || host.is_unspecified()) {
    host = con->get_raw_socket().local_endpoint(ec).address();
    if (ec) return "localhost";
  }
  if (host.is_v6() && host.to_v6().is_v4_mapped()) host = asio::ip::make_address_v4(asio::ip::v4_mapped, host.to_v6());
  return host.is_v6() ? "[" + host.to_string() + "]" : host.to_string();
}

// Every GET and HEAD on the redirect port: 308 to the same path and query over https on the
// node's port, at the host the request named (its Host header, checked: http::redirect_host),
// else at the node's address. Other methods get 405. No content, no HSTS (plain HTTP).
template <class Config>
void Endpoint<Config>::on_redirect_http(connection_hdl h) {
  namespace sc = websocketpp::http::status_code;
  websocketpp::lib::error_code ec;
  auto con = redirect->get_con_from_hdl(h, ec);
  if (ec) return;
  const std::string& method = con->get_request().get_method();
  if (method != "GET" && method != "HEAD") {
    respond(con, false, sc::method_not_allowed, "method not allowed: this port redirects GET and HEAD to https\n");
    con->replace_header("Allow", "GET, HEAD");
    return;
  }
  const std::string host = http::redirect_host(con->get_request_header("Host")).value_or(fallback_host(con));
  const std::string to = http::location("https", host, bound_port, con->get_resource());
  respond(con, method == "HEAD", sc::ok, "moved permanently to " + to + "\n");
  con->set_status(static_cast<sc::value>(308), "Permanent Redirect");  // not in websocketpp's table
  con->replace_header("Location", to);
}

// A WebSocket upgrade on the redirect port: refused (a WebSocket does not follow redirects), and
// the body says where the secure one is.
template <class Config>
bool Endpoint<Config>::on_redirect_validate(connection_hdl h) {
  auto con = redirect->get_con_from_hdl(h);
  const std::string host = http::redirect_host(con->get_request_header("Host")).value_or(fallback_host(con));
  con->set_status(websocketpp::http::status_code::forbidden);
  con->set_body("plain WebSocket is not served: this port only redirects to https; the WebSocket is " +
                http::location("wss", host, bound_port, "/ws") + "\n");
  con->replace_header("Content-Type", "text/plain; charset=utf-8");
  log(Event(Ev::rejected, "plain WebSocket on the redirect port").with("address", peer_address(con)));
  return false;
}

template <class Config>
void Endpoint<Config>::stop() {
  Endpoint& i = *this;
  if (!i.running) return;
  i.running = false;
  std::promise<void> done;
  i.ws.get_io_service().post([&i, &done] {
    websocketpp::lib::error_code ec;
    i.ws.stop_listening(ec);
    if (i.redirect) i.redirect->stop_listening(ec);
    if (i.poll) i.poll->cancel();
    for (auto& [h, c] : i.conns) {
      c->sink->open = false;
      c->closing = true;
      caf::anon_send_exit(c->session, caf::exit_reason::user_shutdown);
      i.ws.close(h, websocketpp::close::status::going_away, "server stopping", ec);
    }
    for (auto& [t, v] : i.mjpeg)
      for (auto& s : v) s->shutdown();
    i.mjpeg.clear();
    i.last_mjpeg.clear();
    done.set_value();
  });
  done.get_future().wait_for(std::chrono::seconds(2));
  // Give close handshakes a moment, then stop the loop whatever is left.
  for (int k = 0; k < 100 && !i.ws.stopped(); ++k) {
    if (i.open_conns == 0) break;
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  i.ws.stop();
  if (i.thread.joinable()) i.thread.join();
  for (auto& [h, c] : i.conns) caf::anon_send_exit(c->session, caf::exit_reason::user_shutdown);
  i.conns.clear();
  i.count = 0;
}

}  // namespace

Server::Server(caf::actor_system& sys, std::shared_ptr<const NodeSettings> settings, ServerOptions options) {
  if (options.tls())
    impl_ = std::make_shared<Endpoint<websocketpp::config::asio_tls>>(sys, std::move(settings), std::move(options));
  else
    impl_ = std::make_shared<Endpoint<websocketpp::config::asio>>(sys, std::move(settings), std::move(options));
}

Server::~Server() { stop(); }

void Server::start() { impl_->start(); }
void Server::stop() { impl_->stop(); }
uint16_t Server::port() const { return impl_->bound_port; }
size_t Server::sessions() const { return impl_->count; }
uint64_t Server::queued_bytes() const { return impl_->queued; }
size_t Server::mjpeg_viewers() const { return impl_->viewers; }
uint16_t Server::redirect_port() const { return impl_->redirect_bound; }
bool Server::reload_tls(std::string* error) { return impl_->reload_tls(error); }

}  // namespace tessera
