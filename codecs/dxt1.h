#pragma once
// S3TC / DXT1 display encoding with libsquish, laid out for WebGL.
//
// Layout (what compressedTexImage2D(TEXTURE_2D, 0, COMPRESSED_RGB_S3TC_DXT1_EXT, w, h, 0,
// data) expects): the image is cut into 4x4 blocks, bw = ceil(width/4) per row and
// bh = ceil(height/4) rows, stored row-major from the top row of the image (row 0 first),
// 8 bytes per block: color0 (RGB565, little endian), color1 (RGB565, little endian), then
// 32 bits of 2-bit indices, texel (x, y) of the block at bits 2*(4*y + x). Total
// bw * bh * 8 bytes.
//
// Padding: the encoded image is the image padded to 4*bw x 4*bh; the client uploads it with
// compressedTexImage2D(..., COMPRESSED_RGB_S3TC_DXT1_EXT, 4*bw, 4*bh, ...) (always valid,
// also where a WebGL implementation insists on multiples of 4) and shows only the top-left
// width x height texels (texture coordinates width/(4*bw), height/(4*bh)). Padding texels
// repeat the image's last column/row but are excluded from the colour fit, so their decoded
// values are unspecified. Row 0 is the top of the image: compressed uploads ignore
// UNPACK_FLIP_Y, so the client flips v when drawing.
#include <cstddef>
#include <cstdint>
#include <vector>

#include "core/image.h"

namespace tessera {

enum class Dxt1Fit : uint8_t {
  range = 0,    // squish's range fit: fast (the default for frames)
  cluster = 1,  // squish's cluster fit: several times slower, higher quality
};

// Bytes of a DXT1 image of width x height: ceil(w/4) * ceil(h/4) * 8 (0 for an empty image).
size_t dxt1_size(int width, int height);

// Encodes RGBA8 (alpha ignored, RGB mode) into `blocks` (dxt1_size bytes). Block rows are
// compressed in parallel with TBB, in the caller's task arena (its concurrency is the thread
// count); libsquish's own OpenMP loop is not used (each block is compressed on its own).
void dxt1_encode(const uint8_t* rgba, int width, int height, Dxt1Fit fit, uint8_t* blocks);
// Same, into `out` from `offset` on (bytes before it kept); `out` resized to offset + size.
void dxt1_encode(const Image& img, Dxt1Fit fit, std::vector<uint8_t>& out, size_t offset = 0);

// Reference decoder written from the S3TC specification (not from libsquish):
// color0 > color1 (as 16-bit numbers): four colours c0, c1, (2*c0 + c1)/3, (c0 + 2*c1)/3;
// otherwise three colours c0, c1, (c0 + c1)/2 and black. RGB565 is expanded to 8 bits by bit
// replication and the interpolations round down (as libsquish does; the specification leaves
// the rounding to the implementation). Index 3 in three-colour mode is opaque black for
// COMPRESSED_RGB_S3TC_DXT1_EXT; with `transparent_black` its alpha is 0 instead (RGBA_DXT1,
// and what squish::DecompressImage writes).
Image dxt1_decode(const uint8_t* blocks, int width, int height, bool transparent_black = false);

}  // namespace tessera
