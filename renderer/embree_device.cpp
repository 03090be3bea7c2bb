#include "renderer/embree_device.h"

#include <cstdio>
#include <stdexcept>

namespace tessera {

namespace {

std::mutex g_mu;
std::weak_ptr<EmbreeDevice> g_device;
std::atomic<uint64_t> g_geometry_limit{uint64_t(1) << 30};
std::atomic<bool> g_high_quality_bvh{false};

const char* code_name(RTCError code) {
  switch (code) {
    case RTC_ERROR_NONE: return "none";
    case RTC_ERROR_UNKNOWN: return "unknown error";
    case RTC_ERROR_INVALID_ARGUMENT: return "invalid argument";
    case RTC_ERROR_INVALID_OPERATION: return "invalid operation";
    case RTC_ERROR_OUT_OF_MEMORY: return "out of memory";
    case RTC_ERROR_UNSUPPORTED_CPU: return "unsupported CPU";
    case RTC_ERROR_CANCELLED: return "cancelled";
  }
  return "error";
}

}  // namespace

std::shared_ptr<EmbreeDevice> EmbreeDevice::acquire() {
  std::lock_guard<std::mutex> l(g_mu);
  if (auto d = g_device.lock()) return d;
  std::shared_ptr<EmbreeDevice> d(new EmbreeDevice());
  g_device = d;
  return d;
}

size_t EmbreeDevice::live() {
  std::lock_guard<std::mutex> l(g_mu);
  return g_device.expired() ? 0 : 1;
}

void EmbreeDevice::set_geometry_cache_limit(uint64_t bytes) {
  std::lock_guard<std::mutex> l(g_mu);
  g_geometry_limit.store(bytes);
  if (auto d = g_device.lock()) d->geometries_.set_limit(bytes);
}

void EmbreeDevice::set_high_quality_bvh(bool high) { g_high_quality_bvh.store(high); }
bool EmbreeDevice::high_quality_bvh() { return g_high_quality_bvh.load(); }

bool EmbreeDevice::geometry_stats(GeometryCache::Stats& out) {
  std::shared_ptr<EmbreeDevice> d;
  {
    std::lock_guard<std::mutex> l(g_mu);
    d = g_device.lock();
  }
  if (!d) return false;
  out = d->geometries_.stats();
  return true;  // `d` may be the last holder: released here, outside g_mu
}

EmbreeDevice::EmbreeDevice() : geometries_(g_geometry_limit.load()) {
  device_ = rtcNewDevice(nullptr);
  if (!device_) throw std::runtime_error("cannot create the Embree device: " + std::string(code_name(rtcGetDeviceError(nullptr))));
  rtcSetDeviceErrorFunction(device_, on_error, this);
}

EmbreeDevice::~EmbreeDevice() {
  geometries_.clear();  // its scenes before the device
  rtcReleaseDevice(device_);
}

std::string EmbreeDevice::last_error() const {
  std::lock_guard<std::mutex> l(mu_);
  return last_;
}

void EmbreeDevice::on_error(void* self, RTCError code, const char* message) {
  auto* d = static_cast<EmbreeDevice*>(self);
  std::string what = std::string("embree: ") + code_name(code) + ": " + (message ? message : "");
  std::fprintf(stderr, "%s\n", what.c_str());  // the operator sees it even when no frame fails
  {
    std::lock_guard<std::mutex> l(d->mu_);
    d->last_ = std::move(what);
  }
  d->errors_.fetch_add(1, std::memory_order_release);
}

}  // namespace tessera
