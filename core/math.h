#pragma once
// Small vector and matrix types for the scene model and shading. Matrices are
// column-major 4x4 (as glTF and WebGL store them): m[col * 4 + row].
#include <array>
#include <cmath>

namespace tessera {

struct Vec3 {
  float x = 0, y = 0, z = 0;
  constexpr Vec3() = default;
  constexpr Vec3(float a, float b, float c) : x(a), y(b), z(c) {}
  constexpr explicit Vec3(float s) : x(s), y(s), z(s) {}
  constexpr float operator[](int i) const { return i == 0 ? x : (i == 1 ? y : z); }
  constexpr Vec3 operator+(const Vec3& o) const { return {x + o.x, y + o.y, z + o.z}; }
  constexpr Vec3 operator-(const Vec3& o) const { return {x - o.x, y - o.y, z - o.z}; }
  constexpr Vec3 operator*(const Vec3& o) const { return {x * o.x, y * o.y, z * o.z}; }
  constexpr Vec3 operator*(float s) const { return {x * s, y * s, z * s}; }
  constexpr Vec3 operator/(float s) const { return {x / s, y / s, z / s}; }
  constexpr Vec3 operator-() const { return {-x, -y, -z}; }
  Vec3& operator+=(const Vec3& o) { x += o.x; y += o.y; z += o.z; return *this; }
  Vec3& operator*=(float s) { x *= s; y *= s; z *= s; return *this; }
  friend constexpr bool operator==(const Vec3& a, const Vec3& b) { return a.x == b.x && a.y == b.y && a.z == b.z; }
  friend constexpr bool operator!=(const Vec3& a, const Vec3& b) { return !(a == b); }
};
inline constexpr Vec3 operator*(float s, const Vec3& v) { return v * s; }
inline constexpr float dot(const Vec3& a, const Vec3& b) { return a.x * b.x + a.y * b.y + a.z * b.z; }
inline constexpr Vec3 cross(const Vec3& a, const Vec3& b) {
  return {a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x};
}
inline float length(const Vec3& v) { return std::sqrt(dot(v, v)); }
inline Vec3 normalize(const Vec3& v) {
  float l = length(v);
  return l > 0 ? v / l : Vec3{0, 0, 0};
}
inline bool finite(const Vec3& v) { return std::isfinite(v.x) && std::isfinite(v.y) && std::isfinite(v.z); }
inline float max_component(const Vec3& v) { return std::fmax(v.x, std::fmax(v.y, v.z)); }

struct Mat4 {
  std::array<float, 16> m{1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1};

  static Mat4 identity() { return {}; }
  static Mat4 translate(const Vec3& t) {
    Mat4 r;
    r.m[12] = t.x; r.m[13] = t.y; r.m[14] = t.z;
    return r;
  }
  static Mat4 scale(const Vec3& s) {
    Mat4 r;
    r.m[0] = s.x; r.m[5] = s.y; r.m[10] = s.z;
    return r;
  }
  // Rotation about a unit axis by an angle in radians (XML3D's axis-angle).
  static Mat4 rotate(const Vec3& axis, float angle);
  // Camera-to-world for a camera at eye looking at target (camera looks down -Z, +Y up).
  static Mat4 look_at(const Vec3& eye, const Vec3& target, const Vec3& up);

  float operator()(int row, int col) const { return m[col * 4 + row]; }
  float& operator()(int row, int col) { return m[col * 4 + row]; }

  Vec3 transform_point(const Vec3& p) const {
    return {m[0] * p.x + m[4] * p.y + m[8] * p.z + m[12], m[1] * p.x + m[5] * p.y + m[9] * p.z + m[13],
            m[2] * p.x + m[6] * p.y + m[10] * p.z + m[14]};
  }
  Vec3 transform_vector(const Vec3& v) const {
    return {m[0] * v.x + m[4] * v.y + m[8] * v.z, m[1] * v.x + m[5] * v.y + m[9] * v.z,
            m[2] * v.x + m[6] * v.y + m[10] * v.z};
  }
  float det3() const;  // determinant of the upper-left 3x3 (negative: mirrored)
  bool finite() const {
    for (float v : m)
      if (!std::isfinite(v)) return false;
    return true;
  }
  friend bool operator==(const Mat4& a, const Mat4& b) { return a.m == b.m; }
  friend bool operator!=(const Mat4& a, const Mat4& b) { return a.m != b.m; }
};

Mat4 operator*(const Mat4& a, const Mat4& b);
Mat4 inverse(const Mat4& a);  // general 4x4 inverse; identity if singular
Mat4 transpose(const Mat4& a);

constexpr float kPi = 3.14159265358979323846f;

}  // namespace tessera
