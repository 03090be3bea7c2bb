#pragma once
// Samples of progressive rendering (RenderSettings::sample > 0): a frame's sample s adds one
// sub-pixel position and S ambient-occlusion directions per hit to the pixels it averages with
// the frame's other samples. Both come from the first two dimensions of the Sobol sequence,
// a (0,2)-sequence in base 2: any 2^k consecutive points from index m*2^k on are stratified
// over the unit square in every elementary interval of area 2^-k. Each pixel and each use
// (jitter, AO at each depth) gets its own Owen scrambling of the points (hash-based nested
// uniform scrambling, Burley 2020, "Practical Hash-based Owen Scrambling", JCGT 9(4)) and its
// own shuffle of the indices (the same scrambling applied to the index), which keeps that
// stratification, makes every point uniform (so the average is unbiased), and decorrelates
// the uses from one another: with unshuffled indices, sample s's jitter and its AO direction
// would be the same point under two shifts, and the average would converge to something else.
//
// Sample 0 is the pixel centre with the fixed path's AO pattern, so a frame's first sample
// is exactly the frame a non-progressive render shows.
#include <cstdint>

namespace tessera::sampling {

// Bits of the first Sobol dimension (van der Corput in base 2): i with its bits reversed.
inline uint32_t sobol0(uint32_t i) {
  i = (i << 16) | (i >> 16);
  i = ((i & 0x55555555u) << 1) | ((i & 0xAAAAAAAAu) >> 1);
  i = ((i & 0x33333333u) << 2) | ((i & 0xCCCCCCCCu) >> 2);
  i = ((i & 0x0F0F0F0Fu) << 4) | ((i & 0xF0F0F0F0u) >> 4);
  i = ((i & 0x00FF00FFu) << 8) | ((i & 0xFF00FF00u) >> 8);
  return i;
}

// The positions of i's set bits, summed over supersets: bit m of the result is the xor of the
// bits j of i whose positions contain m's (j & m == m), five butterfly steps with no branch.
inline uint32_t superset_xor(uint32_t i) {
  i ^= (i >> 1) & 0x55555555u;
  i ^= (i >> 2) & 0x33333333u;
  i ^= (i >> 4) & 0x0F0F0F0Fu;
  i ^= (i >> 8) & 0x00FF00FFu;
  i ^= (i >> 16) & 0x0000FFFFu;
  return i;
}

// Bits of the second Sobol dimension (primitive polynomial x + 1: direction numbers
// v_1 = 1/2, v_j = v_(j-1) xor v_(j-1)/2). Bit 31 - m of v_j is C(j, m) mod 2, odd exactly when
// m's bits are a subset of j's (Lucas), so the sum over i's set bits is superset_xor(i)
// bit-reversed. (The loop over the bits it replaces, `if (i & 1) r ^= v`, branched on random
// bits of scrambled indices: 15-25% of a progressive sample's time on the pavilion.)
inline uint32_t sobol1(uint32_t i) { return sobol0(superset_xor(i)); }

inline uint32_t mix(uint32_t x) {
  x ^= x >> 16; x *= 0x7feb352dU; x ^= x >> 15; x *= 0x846ca68bU; x ^= x >> 16;
  return x;
}

// The per-pixel seed of a frame (the frame number decorrelates consecutive stills).
inline uint32_t pixel_seed(int x, int y, uint32_t frame) {
  return mix(uint32_t(x) * 0x8DA6B343u ^ mix(uint32_t(y) * 0xD8163841u ^ mix(frame * 0x9E3779B9u + 0x632BE5ABu)));
}

// A random permutation of the bits of x in which bit j of the result depends only on bits
// 0..j of x (Laine and Karras 2011; the multipliers of Burley 2020).
inline uint32_t lk_permutation(uint32_t x, uint32_t seed) {
  x += seed;
  x ^= x * 0x6c50b47cu;
  x ^= x * 0xb82f1e52u;
  x ^= x * 0xc7afe638u;
  x ^= x * 0x8d22f6e6u;
  return x;
}

// Nested uniform (Owen) scrambling of a 32-bit fraction: bit j (from the top) is flipped
// depending on the bits above it only.
// (sobol0 reverses the bits.)
inline uint32_t owen(uint32_t bits, uint32_t seed) { return sobol0(lk_permutation(sobol0(bits), seed)); }

// Point i of the sequence of one pixel (`seed`) and one use (`salt`), in [0, 1)^2.
struct Point { float u, v; };
inline Point shifted(uint32_t i, uint32_t seed, uint32_t salt) {
  const uint32_t key = mix(seed ^ salt);
  const uint32_t index = owen(i, key);  // blocks of 2^k aligned indices stay together
  // owen(sobol0(index), k) and owen(sobol1(index), k), with the two bit reversals that cancel
  // (sobol0 is its own inverse) left out.
  const uint32_t a = sobol0(lk_permutation(index, mix(key ^ 0x5BD1E995u)));
  const uint32_t b = sobol0(lk_permutation(superset_xor(index), mix(key ^ 0x1B873593u)));
  constexpr float k = 5.9604644775390625e-08f;  // 2^-24: the top 24 bits, so that u, v < 1 in float
  return {float(a >> 8) * k, float(b >> 8) * k};
}

// AO rays per hit in each sample of a refining still after its first: the node's default
// (still-ao-samples) and tessera quality's for the refining modes. The average converges to
// the same image whatever the count; the count sets how soon. A sample with S rays costs about
// C + S A (C the rest of the sample, A a ray's share) and leaves a variance of about
// V_pixel + V_ao / S, so the error after a given time is least near S = sqrt(C V_ao / (A V_pixel)):
// more rays where AO noise outweighs the anti-aliasing's and a ray is cheap beside the rest.
// Measured on the shared scenes (docs/renderer.md, "AO rays per sample of a still"), 3 to 6
// rays reach 35 and 40 dB 1.3-2x sooner than 1. Four keeps each sample's rays an aligned block
// of the pixel's Sobol points (stratified on their own).
constexpr int kStillAoSamples = 4;

constexpr uint32_t kJitterSalt = 0xA511E9B3u;
inline uint32_t ao_salt(int depth) { return 0x63D83595u + uint32_t(depth) * 0x9E3779B9u; }

// Sub-pixel position of sample s (> 0) of a pixel, in [0, 1)^2; sample 0 is the centre.
inline Point jitter(uint32_t sample, uint32_t seed) {
  if (sample == 0) return {0.5f, 0.5f};
  return shifted(sample, seed, kJitterSalt);
}

}  // namespace tessera::sampling
