#pragma once
// Where a session's server messages go: the client's WebSocket (and its MJPEG streams).
// Implemented by the network layer (net/server.cpp) and by tests. Calls come from actor
// threads; implementations must be thread-safe and must not block.
#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <vector>

namespace tessera {

class ClientSink {
 public:
  virtual ~ClientSink() = default;
  // One binary WebSocket message (a complete protocol message).
  virtual void send(std::vector<uint8_t> message) = 0;
  // A Frame record. A client that has not read the frames before it gets the newest: the
  // network layer keeps at most one frame waiting per connection and a newer one replaces it
  // (net/server.cpp). Default: send().
  virtual void send_frame(std::vector<uint8_t> message) { send(std::move(message)); }
  // Frames replaced that way so far (reported in Stats.dropped). Any thread.
  virtual uint32_t frames_dropped() const { return 0; }
  // Frames given to send_frame that the network layer has not yet handed to the socket (nor
  // replaced). Any thread. The H.264 display encodes its next frame only when this is 0, so no
  // frame of a video stream is ever replaced: the decoder needs every one (actors/display_actor.cpp).
  virtual uint32_t frames_unsent() const { return 0; }
  // `f` is called (on the network layer's thread) whenever a frame given to send_frame has
  // been written to the socket or replaced, i.e. when frames_unsent() has fallen. Set once,
  // before the first frame; the display actor uses it to encode its waiting frame.
  virtual void on_frame_gone(std::function<void()> f) { (void)f; }
  // How fast the connection has lately drained frames that waited for it, in kbit/s (smoothed;
  // net/link_meter.h); 0 when it has not been measured in the last two seconds (a link that
  // keeps up is not measured). The H.264 display fits its bitrate to it. Any thread.
  virtual uint32_t link_kbps() const { return 0; }
  // Frames given to send_frame that found the connection still holding an earlier frame for
  // the link (they had to wait instead of going to the socket at once), so far. While it grows
  // the link, not rendering, bounds the frame rate. Any thread.
  virtual uint32_t frames_waited() const { return 0; }
  // The link has lately been saturated: bytes waited in the kernel for it most of the time
  // (net/link_meter.h), so frames wait for it there even if none waits in the node. Any thread.
  virtual bool link_saturated() const { return false; }
  // One JPEG for the session's MJPEG streams (multipart/x-mixed-replace on HTTP), the picture
  // of the client's frame `frame` (its part's X-Tessera-Frame header).
  virtual void send_mjpeg(std::shared_ptr<const std::vector<uint8_t>> jpeg, uint32_t frame) = 0;
  // Ends the connection after a fatal protocol error (the session has sent the error).
  virtual void close(const std::string& reason) = 0;
  // The session token (names the MJPEG endpoint /mjpeg/<token>); may be empty.
  virtual std::string token() const = 0;
  // "http://host:port" (or https) as the client reached this node: its WebSocket's Host header.
  // References to files under this origin's /scenes/ are read from the node's scenes folder
  // (update/asset_store.h). "": unknown (the client's references name no file of this node).
  virtual std::string node_origin() const { return ""; }
  // The session has taken one client message of `bytes` bytes from its mailbox (any thread):
  // the connection stops reading while too many wait there, and reads on once they are taken.
  virtual void consumed(size_t bytes) { (void)bytes; }
};

}  // namespace tessera
