#pragma once
// H.264 video display encoding with Cisco's OpenH264 (Debian's libopenh264, BSD-2-Clause).
//
// The encoder is set up for interaction, not for storage: constrained baseline profile (no
// B-frames, CAVLC), one slice, one reference frame, one thread, no frame skipping and no
// look-ahead, so every frame in gives one access unit out at once. Rate control aims at a
// bitrate that can change between frames. Keyframes (IDR) come on demand: the first frame, a
// size change, or a caller's request; there is no periodic keyframe.
//
// Colours: RGB is converted to 4:2:0 YCbCr with the BT.709 matrix, limited range, and the
// stream says so in its VUI (colour primaries, transfer and matrix BT.709), so a browser's
// decoder converts back with the same matrix. Odd widths and heights are padded by one
// replicated column or row (4:2:0 needs even sizes); the decoder's picture is cropped back.
#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "core/image.h"

class ISVCEncoder;
class ISVCDecoder;

namespace tessera {

// Bitrates a client or a node may ask for (kbit/s).
constexpr uint32_t kH264MinKbps = 100;
constexpr uint32_t kH264MaxKbps = 200000;
// The largest picture: H.264 level 5.2 (36,864 macroblocks of 16x16 pixels).
constexpr uint64_t kH264MaxMacroblocks = 36864;

// What one encode produced.
struct H264Unit {
  bool keyframe = false;  // an IDR access unit (SPS, PPS and an IDR slice)
  size_t bytes = 0;       // bytes appended after the offset
};

class H264Encoder {
 public:
  // threads > 1: OpenH264 codes that many slices of each picture in parallel (a few percent
  // more bytes; the node uses 1, as its encoder runs beside the render threads).
  explicit H264Encoder(int threads = 1) : threads_(threads < 1 ? 1 : (threads > 4 ? 4 : threads)) {}
  ~H264Encoder();
  H264Encoder(const H264Encoder&) = delete;
  H264Encoder& operator=(const H264Encoder&) = delete;

  // Encodes width x height RGBA8 pixels (row 0 at the top, alpha ignored) as one access unit
  // in Annex B form (start codes before each NAL unit), written into `out` from `offset` on
  // (bytes before it are kept; `out` is resized to offset + the unit's size).
  //  - The first frame, and the first after a size change, is a keyframe; `keyframe` asks for
  //    one now (a new viewer, a decoder that lost its place).
  //  - bitrate_kbps (kH264MinKbps..kH264MaxKbps) is the rate control's target from this frame
  //    on; fps is the frame rate it spreads the bitrate over (1..240).
  // Returns false and sets `error` (bad arguments, a size beyond level 5.2, an OpenH264
  // failure); the next call starts a fresh stream.
  bool encode(const uint8_t* rgba, int width, int height, uint32_t bitrate_kbps, float fps, bool keyframe,
              std::vector<uint8_t>& out, H264Unit& unit, std::string& error, size_t offset = 0);

  uint64_t keyframes() const { return keyframes_; }
  uint64_t frames() const { return frames_; }

 private:
  bool open(int width, int height, uint32_t bitrate_kbps, float fps, std::string& error);
  void close();

  ISVCEncoder* enc_ = nullptr;
  int threads_ = 1;
  int width_ = 0, height_ = 0;  // the picture's size (even; the frames' may be one less)
  uint32_t kbps_ = 0;          // the caller's target
  uint32_t applied_bps_ = 0;   // what OpenH264's rate control has now (see idr_boost_)
  double idr_boost_ = 1;       // applied / target for the P-frames that share a keyframe's window
  uint32_t since_idr_ = 0;     // frames coded since the last keyframe
  float fps_ = 0;
  std::vector<uint8_t> yuv_;  // I420 planes of the padded picture
  uint64_t keyframes_ = 0, frames_ = 0;
};

// Decodes an H.264 stream one access unit at a time (tests and benches: the browser decodes
// with WebCodecs). Not thread-safe.
class H264Decoder {
 public:
  H264Decoder();
  ~H264Decoder();
  H264Decoder(const H264Decoder&) = delete;
  H264Decoder& operator=(const H264Decoder&) = delete;

  // Decodes one access unit (Annex B). On a picture, returns true with `out` set to it as
  // RGBA8, cropped to width x height (the frame's size; 0 keeps the picture's). Returns false
  // and sets `error` when the unit cannot be decoded or gives no picture.
  bool decode(const uint8_t* data, size_t size, Image& out, std::string& error, int width = 0, int height = 0);

 private:
  ISVCDecoder* dec_ = nullptr;
};

// The NAL unit types of an Annex B access unit, in order (e.g. 7 SPS, 8 PPS, 5 IDR slice,
// 1 non-IDR slice). Empty when `data` does not start with a start code.
std::vector<int> h264_nal_types(const uint8_t* data, size_t size);

}  // namespace tessera
