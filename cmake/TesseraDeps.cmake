# Finds the Debian 12 packages Tessera depends on and wraps the ones without a
# CMake config as imported targets (facts in ../shared/STACK.md).
find_package(Threads REQUIRED)
find_package(embree 3 REQUIRED)
find_package(TBB REQUIRED COMPONENTS tbb)
find_package(ZLIB REQUIRED)
find_package(libjpeg-turbo REQUIRED)
find_package(websocketpp REQUIRED)
find_package(Catch2 2 REQUIRED)
# libcrypto: HMAC-SHA256 of access tokens (net/admission.h); libssl: HTTPS/WSS (net/tls.h) and the
# cluster's mutual TLS (CAF's OpenSSL module, and the node's own checks of its certificate files,
# app/cluster_tls.h).
find_package(OpenSSL REQUIRED COMPONENTS Crypto SSL)
# OpenH264 2.3 (libopenh264-dev, BSD-2-Clause): the H.264 video display (codecs/h264.h).
find_package(PkgConfig REQUIRED)
pkg_check_modules(openh264 REQUIRED IMPORTED_TARGET openh264)

# CAF 0.17.6: no CMake config and no .pc file.
find_path(CAF_INCLUDE_DIR caf/all.hpp REQUIRED)
find_library(CAF_CORE_LIBRARY caf_core REQUIRED)
find_library(CAF_IO_LIBRARY caf_io REQUIRED)
add_library(caf::core UNKNOWN IMPORTED)
set_target_properties(caf::core PROPERTIES IMPORTED_LOCATION ${CAF_CORE_LIBRARY}
  INTERFACE_INCLUDE_DIRECTORIES ${CAF_INCLUDE_DIR}
  INTERFACE_LINK_LIBRARIES Threads::Threads)
add_library(caf::io UNKNOWN IMPORTED)
set_target_properties(caf::io PROPERTIES IMPORTED_LOCATION ${CAF_IO_LIBRARY}
  INTERFACE_LINK_LIBRARIES caf::core)
# CAF's OpenSSL module (libcaf-openssl0.17, a dependency of libcaf-dev): the middleman over TLS.
# Its headers include <openssl/ssl.h>.
find_path(CAF_OPENSSL_INCLUDE_DIR caf/openssl/manager.hpp REQUIRED)
find_library(CAF_OPENSSL_LIBRARY caf_openssl REQUIRED)
add_library(caf::openssl UNKNOWN IMPORTED)
set_target_properties(caf::openssl PROPERTIES IMPORTED_LOCATION ${CAF_OPENSSL_LIBRARY}
  INTERFACE_INCLUDE_DIRECTORIES ${CAF_OPENSSL_INCLUDE_DIR}
  INTERFACE_LINK_LIBRARIES "caf::io;OpenSSL::SSL")

# libsquish 1.15: its .pc file has an empty prefix.
find_path(SQUISH_INCLUDE_DIR squish.h REQUIRED)
find_library(SQUISH_LIBRARY squish REQUIRED)
add_library(squish::squish UNKNOWN IMPORTED)
set_target_properties(squish::squish PROPERTIES IMPORTED_LOCATION ${SQUISH_LIBRARY}
  INTERFACE_INCLUDE_DIRECTORIES ${SQUISH_INCLUDE_DIR})

# tinygltf (header-only) with stb_image from libstb-dev and nlohmann-json.
find_path(TINYGLTF_INCLUDE_DIR tiny_gltf.h REQUIRED)
find_path(STB_INCLUDE_DIR stb_image.h PATH_SUFFIXES stb REQUIRED)
add_library(tinygltf::tinygltf INTERFACE IMPORTED)
set_target_properties(tinygltf::tinygltf PROPERTIES
  INTERFACE_INCLUDE_DIRECTORIES "${TINYGLTF_INCLUDE_DIR};${STB_INCLUDE_DIR}")
add_library(stb::stb INTERFACE IMPORTED)
set_target_properties(stb::stb PROPERTIES INTERFACE_INCLUDE_DIRECTORIES ${STB_INCLUDE_DIR})
