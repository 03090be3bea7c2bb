// websocketpp's (standalone asio) client behind WsClient.
#include "net/ws_client.h"

#include <chrono>
#include <condition_variable>
#include <deque>
#include <future>
#include <mutex>
#include <thread>

#include <websocketpp/client.hpp>
#include <websocketpp/config/asio_no_tls_client.hpp>

namespace tessera {

using WsClientEndpoint = websocketpp::client<websocketpp::config::asio_client>;
using websocketpp::connection_hdl;

struct WsClient::Impl {
  WsClientEndpoint ep;
  std::thread thread;
  connection_hdl hdl;
  std::mutex mu;
  std::condition_variable cv;
  std::deque<std::vector<uint8_t>> inbox;
  bool opened = false, failed = false, is_closed = false;
  std::string fail_reason;
  uint16_t close_code = 0;
  std::string close_reason;
  int http_status = 0;
};

WsClient::WsClient() : impl_(std::make_unique<Impl>()) {}

WsClient::~WsClient() {
  close();
  impl_->ep.stop();
  if (impl_->thread.joinable()) impl_->thread.join();
}

bool WsClient::connect(const std::string& host, uint16_t port, const std::string& resource, std::string* error,
                       int timeout_ms, const std::vector<std::pair<std::string, std::string>>& headers) {
  Impl& i = *impl_;
  i.ep.clear_access_channels(websocketpp::log::alevel::all);
  i.ep.clear_error_channels(websocketpp::log::elevel::all);
  i.ep.init_asio();
  i.ep.set_max_message_size(256u << 20);
  i.ep.set_tcp_post_init_handler([&i](connection_hdl h) {
    asio::error_code ec;
    i.ep.get_con_from_hdl(h)->get_raw_socket().set_option(asio::ip::tcp::no_delay(true), ec);
  });
  i.ep.set_open_handler([&i](connection_hdl) {
    std::lock_guard<std::mutex> l(i.mu);
    i.opened = true;
    i.cv.notify_all();
  });
  i.ep.set_fail_handler([&i](connection_hdl h) {
    std::lock_guard<std::mutex> l(i.mu);
    i.failed = true;
    i.is_closed = true;
    auto con = i.ep.get_con_from_hdl(h);
    i.http_status = int(con->get_response_code());
    i.fail_reason = "HTTP " + std::to_string(int(con->get_response_code())) + " " + con->get_response_msg() + ": " +
                    con->get_ec().message();
    i.cv.notify_all();
  });
  i.ep.set_close_handler([&i](connection_hdl h) {
    auto con = i.ep.get_con_from_hdl(h);
    std::lock_guard<std::mutex> l(i.mu);
    i.close_code = con->get_remote_close_code();
    i.close_reason = con->get_remote_close_reason();
    i.is_closed = true;
    i.cv.notify_all();
  });
  i.ep.set_message_handler([&i](connection_hdl, WsClientEndpoint::message_ptr m) {
    const std::string& p = m->get_payload();
    std::lock_guard<std::mutex> l(i.mu);
    i.inbox.emplace_back(p.begin(), p.end());
    i.cv.notify_all();
  });
  websocketpp::lib::error_code ec;
  auto con = i.ep.get_connection("ws://" + host + ":" + std::to_string(port) + resource, ec);
  if (ec) {
    if (error) *error = ec.message();
    return false;
  }
  for (const auto& [name, value] : headers) con->replace_header(name, value);
  i.hdl = con->get_handle();
  i.ep.connect(con);
  i.thread = std::thread([&i] {
    try {
      i.ep.run();
    } catch (...) {
    }
  });
  std::unique_lock<std::mutex> l(i.mu);
  i.cv.wait_for(l, std::chrono::milliseconds(timeout_ms), [&] { return i.opened || i.failed; });
  if (!i.opened) {
    if (error) *error = i.failed ? i.fail_reason : "timeout";
    return false;
  }
  return true;
}

bool WsClient::send(const std::vector<uint8_t>& message) {
  websocketpp::lib::error_code ec;
  impl_->ep.send(impl_->hdl, message.data(), message.size(), websocketpp::frame::opcode::binary, ec);
  return !ec;
}

bool WsClient::send_text(const std::string& text) {
  websocketpp::lib::error_code ec;
  impl_->ep.send(impl_->hdl, text, websocketpp::frame::opcode::text, ec);
  return !ec;
}

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

void WsClient::close() {
  Impl& i = *impl_;
  {
    std::lock_guard<std::mutex> l(i.mu);
    if (!i.opened || i.is_closed) return;
  }
  websocketpp::lib::error_code ec;
  i.ep.close(i.hdl, websocketpp::close::status::normal, "bye", ec);
  std::unique_lock<std::mutex> l(i.mu);
  i.cv.wait_for(l, std::chrono::seconds(2), [&] { return i.is_closed; });
}

void WsClient::abort() {
  Impl& i = *impl_;
  std::promise<void> done;
  i.ep.get_io_service().post([&i, &done] {
    websocketpp::lib::error_code ec;
    auto con = i.ep.get_con_from_hdl(i.hdl, ec);
    if (!ec) {
      asio::error_code aec;
      con->get_raw_socket().shutdown(asio::ip::tcp::socket::shutdown_both, aec);
      con->get_raw_socket().close(aec);
    }
    done.set_value();
  });
  done.get_future().wait_for(std::chrono::seconds(2));
  i.ep.stop();
  if (i.thread.joinable()) i.thread.join();
  std::lock_guard<std::mutex> l(i.mu);
  i.is_closed = true;
}

}  // namespace tessera
