#pragma once
// Which instruction set this CPU runs the renderer's wide code in (renderer/raytracer.cpp
// answers once, at first use): AVX-512 (F, VL, DQ, BW, CD with AVX2, FMA and BMI2), or AVX2
// with FMA, BMI2 and F16C. Without either, the SSE2 copies run, which every x86-64 has.

// Code compiled for those sets: between TESSERA_ISA_AVX2_BEGIN (or _AVX512_) and
// TESSERA_ISA_END, GCC generates for the set whose test above says the CPU has it, so the
// target lists and the tests stay together here. clang ignores `#pragma GCC target`
// (-Wunknown-pragmas): its builds (the sanitizer builds) compile one baseline copy instead.
#define TESSERA_PRAGMA(x) _Pragma(#x)
#define TESSERA_ISA_AVX2_BEGIN \
  TESSERA_PRAGMA(GCC push_options) TESSERA_PRAGMA(GCC target("avx2,fma,bmi,bmi2,lzcnt,popcnt,f16c"))
#define TESSERA_ISA_AVX512_BEGIN        \
  TESSERA_PRAGMA(GCC push_options)      \
  TESSERA_PRAGMA(GCC target("avx512f,avx512vl,avx512dq,avx512bw,avx512cd,avx2,fma,bmi,bmi2,lzcnt,popcnt,f16c"))
#define TESSERA_ISA_END TESSERA_PRAGMA(GCC pop_options)

namespace tessera::raytracer_detail {

bool cpu_avx512();
bool cpu_avx2();

}  // namespace tessera::raytracer_detail
