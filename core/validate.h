#pragma once
// Numerical validation of what reaches Embree: transforms, cameras, points and directions.
//
// Fault containment (docs/renderer.md, "Fault containment: what may reach Embree"). Debian
// builds Embree with its assertions on, and an assertion aborts the whole process: every
// session on the node. The assertions that client data can trip are
//   - `all(valid, ray.valid())` at the start of every traversal: each component of a ray's
//     origin and direction must lie in [-FLT_LARGE, FLT_LARGE] (FLT_LARGE = 1.844e18, about
//     2^60.7, Embree's range of valid input numbers) and tnear/tfar must not be NaN. Rays are
//     checked again in object space, after the instance's inverse transform;
//   - `diag[dim] > 0.0f` in the BVH builders, when bounds are infinite or NaN.
// The invariant: every instance transform, camera and light the renderer hands Embree lies
// within the bounds below, and every ray the kernel passes to Embree has origin and direction
// components within kRayLimit (the kernel drops any other ray: the second line). Then every
// object-space ray stays below FLT_LARGE and every bound is finite:
//
//   kWorldLimit = 2^32 (4.3e9): |world coordinate| of any vertex after its mesh transform, of
//     a camera position and of a light position. Hit points and secondary-ray origins lie in
//     this box (plus a relative offset of 1e-4), so world-space ray origins stay within
//     kRayLimit = 2^33; secondary, shadow and AO directions are unit vectors, and primary
//     directions are A (sx, sy, -1) with the camera's 3x3 A bounded below.
//   Mesh transforms (kMeshLimits), A the upper 3x3 and t the translation, norms the maximum
//     absolute row sum (the infinity norm, computed in double):
//     ||A|| <= 2^32 and |t_i| <= 2^32 (nothing placed beyond the world box by the transform
//     alone); ||A^-1|| <= 2^24 (objects scaled down to 6e-8 at most). Object-space rays
//     are A^-1 (o - t) and A^-1 d, so their components are at most 2^24 (2^33 + 2^32) < 2^58,
//     a factor of 8 under FLT_LARGE; object-space vertices are at most 2^24 2^33 = 2^57.
//     cond(A) = ||A|| ||A^-1|| <= 2^20 (about 1e6): float rounding in the instance transform
//     then changes an object-space ray by at most about 2^20 2^-24 = 1/16 of its length in the
//     worst direction; beyond that the picture is noise, and nearly singular transforms (a
//     zero scale, a uniform scale of 1e-30) are refused as singular ones are.
//   Camera transforms (kCameraLimits): the same with ||A|| <= 2^16 and ||A^-1|| <= 2^16, so
//     that primary directions (at most ||A|| (1 + |sx| + |sy|), |sx| <= tan(fov / 2) aspect)
//     stay within kRayLimit for every field of view up to 179 degrees at an aspect of 1000:1.
//     The kernel drops the rays of more extreme combinations (they render as background).
//   The bottom row of a 4x4 matrix must be finite; Embree reads only the 3x4 affine part.
//   Vertex positions must be finite, and |A| max|v| + max|t| <= kWorldLimit per mesh
//   (Scene::validate_mesh, which also holds for scenes built in code).
//
// Each check returns an empty string when the value is acceptable, else what is wrong,
// in words that name the bound (callers prefix the record, field, node or frame).
#include <string>

#include "core/math.h"
#include "core/scene.h"

namespace tessera {

constexpr float kWorldLimit = 4294967296.0f;  // 2^32
constexpr float kRayLimit = 8589934592.0f;    // 2^33: the kernel drops rays with a component beyond it
constexpr float kEmbreeLarge = 1.844e18f;     // Embree's FLT_LARGE (for the documentation and tests)
constexpr float kUnitTolerance = 1e-3f;       // a normalised direction's length is within this of 1

struct TransformLimits {
  double max_norm;          // ||A||, the maximum absolute row sum of the upper 3x3
  double max_inverse_norm;  // ||A^-1||
  double max_condition;     // ||A|| ||A^-1||
  double max_translation;   // |t_i|
};
constexpr TransformLimits kMeshLimits{4294967296.0, 16777216.0, 1048576.0, 4294967296.0};
constexpr TransformLimits kCameraLimits{65536.0, 65536.0, 1048576.0, 4294967296.0};

// Figures of a transform's upper 3x3, computed in double (det 0: norm_inverse and condition are inf).
struct TransformFigures {
  double det = 0, norm = 0, norm_inverse = 0, condition = 0, max_translation = 0;
};
TransformFigures transform_figures(const Mat4& m);

// Empty when all 16 elements are finite and the figures are within `lim`.
std::string check_transform(const Mat4& m, const TransformLimits& lim);
// The same for the figures of a transform already known to be finite (callers that also
// check the world extent compute the figures once).
std::string check_transform(const TransformFigures& f, const TransformLimits& lim);
// A camera: its transform within kCameraLimits and fov_y in (0, pi).
std::string check_camera(const Camera& c);
// A point: finite and every component within kWorldLimit.
std::string check_point(const Vec3& p);
// A direction: finite, and normalising it in float gives a unit vector (not zero, no overflow).
std::string check_direction(const Vec3& d);
// The world box a transform puts vertices with components up to max_abs_vertex in:
// ||A|| max_abs_vertex + max|t_i| <= kWorldLimit, from the transform's figures. Assumes
// check_transform passed.
std::string check_world_extent(const TransformFigures& f, float max_abs_vertex);

}  // namespace tessera
