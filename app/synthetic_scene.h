#pragma once
// A synthetic glTF scene of a chosen size (issue 20: a San Miguel-sized scene for measuring
// loading, which cannot be shipped with the repository). `tessera make-scene` writes one;
// the defaults are San Miguel's figures: 1.6 M unique triangles, 9.5 M with instances, 222
// textures, about 150 MB on disk.
//
// What it holds, all of it deterministic for a seed:
//  - unique meshes: bumpy grids of 2 g^2 triangles (g drawn from 8..48), positions, normals,
//    texture coordinates and uint32 indices, each placed once on a courtyard floor;
//  - instances: nodes that place the first tenth of the meshes again (turned, scaled) until
//    the instanced total is reached, as furniture and plants are in San Miguel;
//  - textures: JPEG files of value noise, each its own colour, one material per texture
//    (meshes take them in turn), and one untextured material when there are none;
//  - a camera over the courtyard and a sun (KHR_lights_punctual), and a camera loop around it.
#include <cstdint>
#include <string>

namespace tessera::app {

struct SyntheticSceneSpec {
  uint64_t unique_triangles = 1'600'000;
  uint64_t instanced_triangles = 9'500'000;  // all triangles drawn, the unique ones included
  int textures = 222;
  int texture_size = 1024;                   // each texture is size x size
  int jpeg_quality = 90;
  uint32_t seed = 1;
};

struct SyntheticSceneFigures {
  uint64_t unique_triangles = 0, instanced_triangles = 0;
  int meshes = 0, nodes = 0, textures = 0, materials = 0;
  uint64_t bin_bytes = 0, texture_bytes = 0, json_bytes = 0;
};

// Writes folder/scene.gltf, folder/scene.bin, folder/textures/t<N>.jpg and a camera loop of
// one turn around the courtyard, folder/camera-loop.json (the folder is created; files of the
// same names are replaced). Throws std::runtime_error when a file
// cannot be written and std::invalid_argument for a spec out of range.
SyntheticSceneFigures write_synthetic_scene(const std::string& folder, const SyntheticSceneSpec& spec);

}  // namespace tessera::app
