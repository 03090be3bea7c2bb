#pragma once
// Which instruction set this CPU runs the renderer's wide code in (renderer/raytracer.cpp
// answers once, at first use): AVX-512 (F, VL, DQ, BW, CD with AVX2, FMA and BMI2), or AVX2
// with FMA, BMI2 and F16C. Without either, the SSE2 copies run, which every x86-64 has.

namespace tessera::raytracer_detail {

bool cpu_avx512();
bool cpu_avx2();

}  // namespace tessera::raytracer_detail
