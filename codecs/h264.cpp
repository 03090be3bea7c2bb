// H.264 with OpenH264 (codecs/h264.h).
#include "codecs/h264.h"

#include <algorithm>
#include <cmath>
#include <cstring>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <wels/codec_api.h>

namespace tessera {
namespace {

// OpenH264's rate control (RC_BITRATE_MODE) shares a budget of kRcWindow frames' bits (its
// "virtual GOP") among the frames of a window that restarts at each keyframe. A keyframe costs
// 2-3 frames' bits at the QP the library picks for it, so the window's P-frames after it got
// what was left: on the shared scenes at 4-6 Mbit/s, 15-25% fewer bytes and 1-2.5 dB less than
// the P-frames after them, and the stream's worst frames (docs/results/display-video.md). For
// those P-frames the encoder raises the rate control's bitrate by the factor that leaves them
// the target's share (a changed bitrate scales the window's remaining bits), and it restores
// the target when the next window starts. The stream then carries the keyframe's excess once
// instead of paying it back within a quarter second.
constexpr uint32_t kRcWindow = 8;
// At most this factor: above 2 the library's floor for a P-frame (half a frame's bits at the
// raised rate) would exceed the target's share.
constexpr double kMaxIdrBoost = 1.8;

// BT.709, limited range, in 16.16 fixed point: Y' = 16 + 219/255 (Kr R + Kg G + Kb B),
// Cb = 128 + 224/255 (B - Y'')/(2 (1 - Kb)), Cr = 128 + 224/255 (R - Y'')/(2 (1 - Kr)).
constexpr double kKr = 0.2126, kKb = 0.0722, kKg = 1 - kKr - kKb;
constexpr int fx(double v) { return int(v * 65536.0 + (v < 0 ? -0.5 : 0.5)); }
constexpr int kYR = fx(219.0 / 255 * kKr), kYG = fx(219.0 / 255 * kKg), kYB = fx(219.0 / 255 * kKb);
constexpr double kCbS = 224.0 / 255 / (2 * (1 - kKb)), kCrS = 224.0 / 255 / (2 * (1 - kKr));
constexpr int kUR = fx(-kKr * kCbS), kUG = fx(-kKg * kCbS), kUB = fx((1 - kKb) * kCbS);
constexpr int kVR = fx((1 - kKr) * kCrS), kVG = fx(-kKg * kCrS), kVB = fx(-kKb * kCrS);

inline uint8_t clamp8(int v) { return uint8_t(v < 0 ? 0 : (v > 255 ? 255 : v)); }

// RGBA (w x h) into the I420 planes of a pw x ph picture (pw, ph even, at most one more than
// w, h): the last column and row are replicated into the padding. Chroma from the mean of
// each 2x2 block. Row pairs are spread over TBB's threads (a 1280x720 frame took 3-4 ms on
// one thread, a quarter of the encode).
void rgba_to_i420(const uint8_t* rgba, int w, int h, int pw, int ph, uint8_t* y, uint8_t* u, uint8_t* v) {
  const int cw = pw / 2;
  auto luma = [](const uint8_t* p) { return uint8_t((kYR * p[0] + kYG * p[1] + kYB * p[2] + (16 << 16) + 32768) >> 16); };
  tbb::parallel_for(tbb::blocked_range<int>(0, ph / 2, 8), [&](const tbb::blocked_range<int>& range) {
    for (int j = range.begin(); j < range.end(); ++j) {
      const uint8_t* r0 = rgba + size_t(std::min(2 * j, h - 1)) * w * 4;
      const uint8_t* r1 = rgba + size_t(std::min(2 * j + 1, h - 1)) * w * 4;
      uint8_t* y0 = y + size_t(2 * j) * pw;
      uint8_t* y1 = y0 + pw;
      uint8_t* uo = u + size_t(j) * cw;
      uint8_t* vo = v + size_t(j) * cw;
      for (int i = 0; i < cw; ++i) {
        const int x0 = 2 * i, x1 = std::min(2 * i + 1, w - 1);
        const uint8_t *a = r0 + x0 * 4, *b = r0 + x1 * 4, *c = r1 + x0 * 4, *d = r1 + x1 * 4;
        y0[x0] = luma(a);
        y0[x0 + 1] = luma(b);
        y1[x0] = luma(c);
        y1[x0 + 1] = luma(d);
        // The sums are 4x the mean: scale by 1/4 inside the rounding shift.
        const int rs = a[0] + b[0] + c[0] + d[0], gs = a[1] + b[1] + c[1] + d[1], bs = a[2] + b[2] + c[2] + d[2];
        uo[i] = clamp8((kUR * rs + kUG * gs + kUB * bs + (128 << 18) + (1 << 17)) >> 18);
        vo[i] = clamp8((kVR * rs + kVG * gs + kVB * bs + (128 << 18) + (1 << 17)) >> 18);
      }
    }
  });
}

// The inverse, for the decoder: BT.709 limited range to RGB.
void i420_to_rgba(const uint8_t* y, const uint8_t* u, const uint8_t* v, int ystride, int cstride, Image& out) {
  constexpr double ys = 255.0 / 219, cs = 255.0 / 224;
  constexpr int kY = fx(ys), kRV = fx(cs * 2 * (1 - kKr)), kBU = fx(cs * 2 * (1 - kKb));
  constexpr int kGU = fx(cs * 2 * (1 - kKb) * kKb / kKg), kGV = fx(cs * 2 * (1 - kKr) * kKr / kKg);
  for (int j = 0; j < out.height; ++j)
    for (int i = 0; i < out.width; ++i) {
      const int yy = kY * (y[size_t(j) * ystride + i] - 16) + 32768;
      const int cb = u[size_t(j / 2) * cstride + i / 2] - 128, cr = v[size_t(j / 2) * cstride + i / 2] - 128;
      uint8_t* p = out.pixel(i, j);
      p[0] = clamp8((yy + kRV * cr) >> 16);
      p[1] = clamp8((yy - kGU * cb - kGV * cr) >> 16);
      p[2] = clamp8((yy + kBU * cb) >> 16);
      p[3] = 255;
    }
}

}  // namespace

H264Encoder::~H264Encoder() { close(); }

void H264Encoder::close() {
  if (enc_) {
    enc_->Uninitialize();
    WelsDestroySVCEncoder(enc_);
    enc_ = nullptr;
  }
  width_ = height_ = 0;
}

bool H264Encoder::open(int width, int height, uint32_t bitrate_kbps, float fps, std::string& error) {
  close();
  if (WelsCreateSVCEncoder(&enc_) != 0 || !enc_) {
    enc_ = nullptr;
    error = "OpenH264: cannot create an encoder";
    return false;
  }
  int trace = WELS_LOG_ERROR;  // OpenH264 writes its warnings to stderr otherwise
  enc_->SetOption(ENCODER_OPTION_TRACE_LEVEL, &trace);
  SEncParamExt p;
  enc_->GetDefaultParams(&p);
  p.iUsageType = CAMERA_VIDEO_REAL_TIME;
  p.iPicWidth = width;
  p.iPicHeight = height;
  p.iTargetBitrate = int(bitrate_kbps) * 1000;
  p.iMaxBitrate = UNSPECIFIED_BIT_RATE;
  p.iRCMode = RC_BITRATE_MODE;
  p.fMaxFrameRate = fps;
  p.iTemporalLayerNum = 1;
  p.iSpatialLayerNum = 1;
  p.uiIntraPeriod = 0;  // keyframes only on demand
  p.iNumRefFrame = 1;
  p.eSpsPpsIdStrategy = CONSTANT_ID;
  p.bPrefixNalAddingCtrl = false;
  p.bSimulcastAVC = false;
  p.iEntropyCodingModeFlag = 0;  // CAVLC (constrained baseline)
  p.bEnableFrameSkip = false;    // every frame in gives a unit out
  p.iComplexityMode = LOW_COMPLEXITY;
  p.iMultipleThreadIdc = threads_;
  p.bEnableDenoise = false;
  p.bEnableBackgroundDetection = false;
  p.bEnableSceneChangeDetect = false;  // keyframes come from the session, not the encoder
  p.bEnableLongTermReference = false;
  p.bEnableAdaptiveQuant = true;
  p.iLoopFilterDisableIdc = 0;
  SSpatialLayerConfig& l = p.sSpatialLayers[0];
  l.iVideoWidth = width;
  l.iVideoHeight = height;
  l.fFrameRate = fps;
  l.iSpatialBitrate = p.iTargetBitrate;
  l.iMaxSpatialBitrate = UNSPECIFIED_BIT_RATE;
  l.uiProfileIdc = PRO_BASELINE;
  l.uiLevelIdc = LEVEL_UNKNOWN;  // the smallest level that fits
  if (threads_ > 1) {
    l.sSliceArgument.uiSliceMode = SM_FIXEDSLCNUM_SLICE;
    l.sSliceArgument.uiSliceNum = unsigned(threads_);
  } else {
    l.sSliceArgument.uiSliceMode = SM_SINGLE_SLICE;
  }
  l.bVideoSignalTypePresent = true;
  l.uiVideoFormat = VF_UNDEF;
  l.bFullRange = false;
  l.bColorDescriptionPresent = true;
  l.uiColorPrimaries = CP_BT709;
  l.uiTransferCharacteristics = TRC_BT709;
  l.uiColorMatrix = CM_BT709;
  if (enc_->InitializeExt(&p) != 0) {
    close();
    error = "OpenH264: the encoder refused " + std::to_string(width) + "x" + std::to_string(height) + " at " +
            std::to_string(bitrate_kbps) + " kbit/s";
    return false;
  }
  int fmt = videoFormatI420;
  enc_->SetOption(ENCODER_OPTION_DATAFORMAT, &fmt);
  width_ = width;
  height_ = height;
  kbps_ = bitrate_kbps;
  applied_bps_ = bitrate_kbps * 1000;
  idr_boost_ = 1;
  since_idr_ = 0;
  fps_ = fps;
  yuv_.assign(size_t(width) * height * 3 / 2, 0);
  return true;
}

bool H264Encoder::encode(const uint8_t* rgba, int width, int height, uint32_t bitrate_kbps, float fps, bool keyframe,
                         std::vector<uint8_t>& out, H264Unit& unit, std::string& error, size_t offset) {
  unit = H264Unit{};
  if (!rgba || width <= 0 || height <= 0) {
    error = "H.264: no image";
    return false;
  }
  if (bitrate_kbps < kH264MinKbps || bitrate_kbps > kH264MaxKbps) {
    error = "H.264: bitrate " + std::to_string(bitrate_kbps) + " kbit/s is outside " + std::to_string(kH264MinKbps) +
            ".." + std::to_string(kH264MaxKbps);
    return false;
  }
  if (!(fps >= 1 && fps <= 240)) fps = 30;
  const int pw = (width + 1) & ~1, ph = (height + 1) & ~1;
  if (uint64_t((pw + 15) / 16) * uint64_t((ph + 15) / 16) > kH264MaxMacroblocks) {
    error = "H.264: " + std::to_string(width) + "x" + std::to_string(height) +
            " is larger than level 5.2 allows (36864 macroblocks)";
    return false;
  }
  if (!enc_ || pw != width_ || ph != height_) {
    if (!open(pw, ph, bitrate_kbps, fps, error)) return false;
    keyframe = true;  // a fresh stream starts with one anyway; counted below
  } else {
    kbps_ = bitrate_kbps;
    if (std::fabs(fps - fps_) > 0.5f) {
      enc_->SetOption(ENCODER_OPTION_FRAME_RATE, &fps);
      fps_ = fps;
    }
    if (keyframe) enc_->ForceIntraFrame(true);
  }
  // The P-frames of a keyframe's window run at the raised rate (kRcWindow), the rest at the target.
  const bool boosted = !keyframe && since_idr_ >= 1 && since_idr_ < kRcWindow;
  const uint32_t want_bps = uint32_t(double(kbps_) * 1000.0 * (boosted ? idr_boost_ : 1.0));
  if (want_bps != applied_bps_) {
    SBitrateInfo b{};
    b.iLayer = SPATIAL_LAYER_ALL;
    b.iBitrate = int(want_bps);
    enc_->SetOption(ENCODER_OPTION_BITRATE, &b);
    applied_bps_ = want_bps;
  }
  uint8_t* y = yuv_.data();
  uint8_t* u = y + size_t(pw) * ph;
  uint8_t* v = u + size_t(pw / 2) * (ph / 2);
  rgba_to_i420(rgba, width, height, pw, ph, y, u, v);

  SSourcePicture pic{};
  pic.iColorFormat = videoFormatI420;
  pic.iPicWidth = pw;
  pic.iPicHeight = ph;
  pic.iStride[0] = pw;
  pic.iStride[1] = pic.iStride[2] = pw / 2;
  pic.pData[0] = y;
  pic.pData[1] = u;
  pic.pData[2] = v;
  pic.uiTimeStamp = (long long)(double(frames_) * 1000.0 / fps_);
  SFrameBSInfo info{};
  if (enc_->EncodeFrame(&pic, &info) != cmResultSuccess) {
    close();
    error = "OpenH264: encoding failed";
    return false;
  }
  if (info.eFrameType == videoFrameTypeSkip || info.eFrameType == videoFrameTypeInvalid) {
    close();  // cannot happen with frame skipping off; a fresh stream keeps the decoder right
    error = "OpenH264: the encoder gave no picture";
    return false;
  }
  size_t total = 0;
  for (int l = 0; l < info.iLayerNum; ++l)
    for (int n = 0; n < info.sLayerInfo[l].iNalCount; ++n) total += size_t(info.sLayerInfo[l].pNalLengthInByte[n]);
  out.resize(offset + total);
  uint8_t* dst = out.data() + offset;
  for (int l = 0; l < info.iLayerNum; ++l) {
    const SLayerBSInfo& li = info.sLayerInfo[l];
    size_t n = 0;
    for (int k = 0; k < li.iNalCount; ++k) n += size_t(li.pNalLengthInByte[k]);
    std::memcpy(dst, li.pBsBuf, n);  // OpenH264 writes Annex B (start codes included)
    dst += n;
  }
  unit.keyframe = info.eFrameType == videoFrameTypeIDR;
  unit.bytes = total;
  frames_++;
  since_idr_++;
  if (unit.keyframe) {
    keyframes_++;
    since_idr_ = 1;
    const double bpf = double(kbps_) * 1000.0 / double(fps_);
    const double left = double(kRcWindow) * bpf - 8.0 * double(total);
    const double want = double(kRcWindow - 1) * bpf;
    // A keyframe beyond the whole window's budget leaves nothing to scale: the library's own
    // rule then holds.
    idr_boost_ = left <= 0 ? 1.0 : std::clamp(want / left, 1.0, kMaxIdrBoost);
  }
  return true;
}

H264Decoder::H264Decoder() {
  if (WelsCreateDecoder(&dec_) != 0 || !dec_) {
    dec_ = nullptr;
    return;
  }
  int trace = WELS_LOG_QUIET;  // a broken unit is reported through decode()'s error
  dec_->SetOption(DECODER_OPTION_TRACE_LEVEL, &trace);
  SDecodingParam p{};
  p.sVideoProperty.eVideoBsType = VIDEO_BITSTREAM_AVC;
  p.eEcActiveIdc = ERROR_CON_DISABLE;  // a broken stream is an error here, not a concealed picture
  if (dec_->Initialize(&p) != 0) {
    WelsDestroyDecoder(dec_);
    dec_ = nullptr;
  }
}

H264Decoder::~H264Decoder() {
  if (dec_) {
    dec_->Uninitialize();
    WelsDestroyDecoder(dec_);
  }
}

bool H264Decoder::decode(const uint8_t* data, size_t size, Image& out, std::string& error, int width, int height) {
  if (!dec_) {
    error = "OpenH264: no decoder";
    return false;
  }
  unsigned char* planes[3] = {nullptr, nullptr, nullptr};
  SBufferInfo info{};
  const DECODING_STATE s = dec_->DecodeFrameNoDelay(data, int(size), planes, &info);
  if (s != dsErrorFree) {
    error = "OpenH264: decoding failed (state " + std::to_string(int(s)) + ")";
    return false;
  }
  if (info.iBufferStatus != 1 || !planes[0]) {
    error = "OpenH264: the unit gave no picture";
    return false;
  }
  const auto& sb = info.UsrData.sSystemBuffer;
  const int w = width > 0 ? std::min(width, sb.iWidth) : sb.iWidth;
  const int h = height > 0 ? std::min(height, sb.iHeight) : sb.iHeight;
  out = Image(w, h);
  i420_to_rgba(planes[0], planes[1], planes[2], sb.iStride[0], sb.iStride[1], out);
  return true;
}

std::vector<int> h264_nal_types(const uint8_t* data, size_t size) {
  std::vector<int> types;
  size_t i = 0;
  auto start_code = [&](size_t at) -> size_t {  // length of a start code at `at`, or 0
    if (at + 3 <= size && data[at] == 0 && data[at + 1] == 0 && data[at + 2] == 1) return 3;
    if (at + 4 <= size && data[at] == 0 && data[at + 1] == 0 && data[at + 2] == 0 && data[at + 3] == 1) return 4;
    return 0;
  };
  if (!start_code(0)) return types;
  while (i < size) {
    const size_t sc = start_code(i);
    if (!sc) {
      ++i;
      continue;
    }
    i += sc;
    if (i < size) types.push_back(data[i] & 0x1f);
  }
  return types;
}

}  // namespace tessera
