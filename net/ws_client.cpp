// websocketpp's (standalone asio) client behind WsClient: plain (ws://) or TLS (wss://).
#include "net/ws_client.h"

#include <chrono>
#include <condition_variable>
#include <deque>
#include <future>
#include <mutex>
#include <thread>

#include <openssl/ssl.h>

#include <websocketpp/client.hpp>
#include <websocketpp/config/asio_client.hpp>  // asio_client (plain) and asio_tls_client

#include "net/tls.h"

namespace tessera {

using websocketpp::connection_hdl;

// What the received messages and the connection's end leave for the caller's thread; the
// endpoint (a template over websocketpp's config) fills it from its network thread.
struct WsClient::Impl {
  virtual ~Impl() = default;
  virtual bool connect(const std::string& host, uint16_t port, const std::string& resource, std::string* error,
                       int timeout_ms, const std::vector<std::pair<std::string, std::string>>& headers) = 0;
  virtual bool send(const void* data, size_t size, bool binary) = 0;
  virtual void close() = 0;
  virtual void abort() = 0;

  std::mutex mu;
  std::condition_variable cv;
  std::deque<std::vector<uint8_t>> inbox;
  bool opened = false, failed = false, is_closed = false;
  std::string fail_reason;
  uint16_t close_code = 0;
  std::string close_reason;
  int http_status = 0;
  std::string tls_session;  // "TLSv1.3 TLS_AES_256_GCM_SHA384" once a TLS connection is open
};

namespace {

template <class Config>
struct Endpoint final : WsClient::Impl {
  using Client = websocketpp::client<Config>;
  static constexpr bool kTls = std::is_same_v<Config, websocketpp::config::asio_tls_client>;
  Client ep;
  std::thread thread;
  connection_hdl hdl;
  std::string ca_file;  // kTls: "" trusts any certificate, else the server's must chain to it

  Endpoint() {  // the io_service from the start: stop() in the destructor needs it, connected or not
    ep.clear_access_channels(websocketpp::log::alevel::all);
    ep.clear_error_channels(websocketpp::log::elevel::all);
    ep.init_asio();
  }
  ~Endpoint() override {
    close();
    ep.stop();
    if (thread.joinable()) thread.join();
  }

  bool connect(const std::string& host, uint16_t port, const std::string& resource, std::string* error,
               int timeout_ms, const std::vector<std::pair<std::string, std::string>>& headers) override {
    ep.set_max_message_size(256u << 20);
    if constexpr (kTls) {
      std::shared_ptr<asio::ssl::context> ctx;
      try {
        ctx = std::make_shared<asio::ssl::context>(tls::client_context(ca_file).release());
      } catch (const std::exception& e) {
        if (error) *error = e.what();
        return false;
      }
      ep.set_tls_init_handler([ctx](connection_hdl) { return ctx; });
      if (!ca_file.empty())  // the certificate must name the host we asked for
        ep.set_socket_init_handler([host](connection_hdl, asio::ssl::stream<asio::ip::tcp::socket>& s) {
          tls::expect_host(s.native_handle(), host);
        });
    }
    ep.set_tcp_post_init_handler([this](connection_hdl h) {
      asio::error_code ec;
      ep.get_con_from_hdl(h)->get_raw_socket().set_option(asio::ip::tcp::no_delay(true), ec);
    });
    ep.set_open_handler([this](connection_hdl h) {
      std::string session;
      if constexpr (kTls) session = tls::describe_session(ep.get_con_from_hdl(h)->get_socket().native_handle());
      std::lock_guard<std::mutex> l(mu);
      opened = true;
      tls_session = session;
      cv.notify_all();
    });
    ep.set_fail_handler([this](connection_hdl h) {
      auto con = ep.get_con_from_hdl(h);
      std::lock_guard<std::mutex> l(mu);
      failed = true;
      is_closed = true;
      http_status = int(con->get_response_code());
      fail_reason = "HTTP " + std::to_string(http_status) + " " + con->get_response_msg() + ": " + con->get_ec().message();
      if (con->get_transport_ec()) fail_reason += " (" + con->get_transport_ec().message() + ")";
      cv.notify_all();
    });
    ep.set_close_handler([this](connection_hdl h) {
      auto con = ep.get_con_from_hdl(h);
      std::lock_guard<std::mutex> l(mu);
      close_code = con->get_remote_close_code();
      close_reason = con->get_remote_close_reason();
      is_closed = true;
      cv.notify_all();
    });
    ep.set_message_handler([this](connection_hdl, typename Client::message_ptr m) {
      const std::string& p = m->get_payload();
      std::lock_guard<std::mutex> l(mu);
      inbox.emplace_back(p.begin(), p.end());
      cv.notify_all();
    });
    websocketpp::lib::error_code ec;
    auto con = ep.get_connection(std::string(kTls ? "wss" : "ws") + "://" + host + ":" + std::to_string(port) + resource, ec);
    if (ec) {
      if (error) *error = ec.message();
      return false;
    }
    for (const auto& [name, value] : headers) con->replace_header(name, value);
    hdl = con->get_handle();
    ep.connect(con);
    thread = std::thread([this] {
      try {
        ep.run();
      } catch (...) {
      }
    });
    std::unique_lock<std::mutex> l(mu);
    cv.wait_for(l, std::chrono::milliseconds(timeout_ms), [&] { return opened || failed; });
    if (!opened) {
      if (error) *error = failed ? fail_reason : "timeout";
      return false;
    }
    return true;
  }

  bool send(const void* data, size_t size, bool binary) override {
    websocketpp::lib::error_code ec;
    ep.send(hdl, data, size, binary ? websocketpp::frame::opcode::binary : websocketpp::frame::opcode::text, ec);
    return !ec;
  }

  void close() override {
    {
      std::lock_guard<std::mutex> l(mu);
      if (!opened || is_closed) return;
    }
    websocketpp::lib::error_code ec;
    ep.close(hdl, websocketpp::close::status::normal, "bye", ec);
    std::unique_lock<std::mutex> l(mu);
    cv.wait_for(l, std::chrono::seconds(2), [&] { return is_closed; });
  }

  void abort() override {
    std::promise<void> done;
    ep.get_io_service().post([this, &done] {
      websocketpp::lib::error_code ec;
      auto con = ep.get_con_from_hdl(hdl, ec);
      if (!ec) {
        asio::error_code aec;
        con->get_raw_socket().shutdown(asio::ip::tcp::socket::shutdown_both, aec);
        con->get_raw_socket().close(aec);
      }
      done.set_value();
    });
    done.get_future().wait_for(std::chrono::seconds(2));
    ep.stop();
    if (thread.joinable()) thread.join();
    std::lock_guard<std::mutex> l(mu);
    is_closed = true;
  }
};

}  // namespace

WsClient::WsClient() : impl_(std::make_unique<Endpoint<websocketpp::config::asio_client>>()) {}

WsClient::~WsClient() = default;

void WsClient::use_tls(const std::string& ca_file) {
  auto e = std::make_unique<Endpoint<websocketpp::config::asio_tls_client>>();
  e->ca_file = ca_file;
  impl_ = std::move(e);
}

bool WsClient::connect(const std::string& host, uint16_t port, const std::string& resource, std::string* error,
                       int timeout_ms, const std::vector<std::pair<std::string, std::string>>& headers) {
  return impl_->connect(host, port, resource, error, timeout_ms, headers);
}

bool WsClient::send(const std::vector<uint8_t>& message) { return impl_->send(message.data(), message.size(), true); }

bool WsClient::send_text(const std::string& text) { return impl_->send(text.data(), text.size(), false); }

std::optional<std::vector<uint8_t>> WsClient::receive(int timeout_ms) {
  Impl& i = *impl_;
  std::unique_lock<std::mutex> l(i.mu);
  i.cv.wait_for(l, std::chrono::milliseconds(timeout_ms), [&] { return !i.inbox.empty() || i.is_closed; });
  if (i.inbox.empty()) return std::nullopt;
  auto m = std::move(i.inbox.front());
  i.inbox.pop_front();
  return m;
}

bool WsClient::closed() const {
  std::lock_guard<std::mutex> l(impl_->mu);
  return impl_->is_closed;
}

uint16_t WsClient::close_code() const {
  std::lock_guard<std::mutex> l(impl_->mu);
  return impl_->close_code;
}

std::string WsClient::close_reason() const {
  std::lock_guard<std::mutex> l(impl_->mu);
  return impl_->close_reason;
}

int WsClient::http_status() const {
  std::lock_guard<std::mutex> l(impl_->mu);
  return impl_->http_status;
}

std::string WsClient::tls_session() const {
  std::lock_guard<std::mutex> l(impl_->mu);
  return impl_->tls_session;
}

void WsClient::close() { impl_->close(); }

void WsClient::abort() { impl_->abort(); }

}  // namespace tessera
