// Typed errors between actors. See errors.h.
#include "actors/errors.h"

#include <algorithm>

#include "actors/checks.h"

#include <caf/message.hpp>
#include <caf/make_message.hpp>

namespace tessera {
namespace protocol {

caf::error make_error(ErrorCode code, std::string message) {
  return caf::error(static_cast<uint8_t>(code), kErrorCategory, caf::make_message(std::move(message)));
}

}  // namespace protocol

protocol::ErrorCode error_code(const caf::error& e, protocol::ErrorCode otherwise) {
  if (!e) return protocol::ErrorCode::ok;
  if (e.category() != kErrorCategory || e.code() == 0) return otherwise;
  return protocol::ErrorCode(e.code());
}

std::string error_message(const caf::error& e) {
  if (!e) return {};
  const caf::message& ctx = e.context();
  if (e.category() == kErrorCategory && ctx.match_elements<std::string>()) return ctx.get_as<std::string>(0);
  return to_string(e);
}

TileResult failed_tile(const RenderTask& t, protocol::ErrorCode code, std::string message) {
  TileResult r;
  r.frame = t.frame;
  r.pixels = t.pixels;
  r.code = code;
  r.error = std::move(message);
  return r;
}

TileResult failed_tile(const RenderTask& t, const caf::error& e, protocol::ErrorCode otherwise) {
  return failed_tile(t, error_code(e, otherwise), error_message(e));
}

BatchReply failed_batch(const RenderBatch& b, protocol::ErrorCode code, const std::string& message) {
  BatchReply r;
  r.tiles.resize(std::min<size_t>(b.tasks.size(), 65536));
  for (size_t i = 0; i < r.tiles.size(); ++i) r.tiles[i] = failed_tile(task_of(b, b.tasks[i]), code, message);
  return r;
}

}  // namespace tessera
