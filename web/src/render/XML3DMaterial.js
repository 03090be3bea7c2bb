// XML3D's matte / diffuse / phong shading (xml3d.js phong.frag.glsl) as a three.js
// ShaderMaterial: world-space lighting with XML3D light semantics (intensity as colour,
// 1/(c + l d + q d^2) attenuation, spot cutoff with softness, specular exponent shininess*128).
// Reflection and refraction are ray-tracing effects: ignored here, except that a refracting
// material is drawn partly transparent so what lies behind glass stays visible.
import * as THREE from './three.js';

export const MAX_LIGHTS = 8;

const vertexShader = /* glsl */`
varying vec3 vWorldPos;
varying vec3 vNormal;
varying vec2 vUv;
varying vec3 vColor;
void main() {
  vec4 wp = modelMatrix * vec4(position, 1.0);
  vWorldPos = wp.xyz;
  vNormal = mat3(transpose(inverse(modelMatrix))) * normal;
#ifdef HAS_UV
  vUv = uv;
#endif
#ifdef HAS_COLOR
  vColor = color;
#endif
  gl_Position = projectionMatrix * viewMatrix * wp;
}`;

const fragmentShader = /* glsl */`
uniform vec3 diffuseColor;
uniform vec3 specularColor;
uniform vec3 emissiveColor;
uniform float shininess;
uniform float ambientIntensity;
uniform float opacity;
uniform float alphaCutoff;
uniform vec3 sceneAmbient;
uniform sampler2D diffuseTexture;
uniform sampler2D specularTexture;
uniform sampler2D emissiveTexture;
#if NUM_POINT > 0
uniform vec3 pointPosition[NUM_POINT];
uniform vec3 pointIntensity[NUM_POINT];
uniform vec3 pointAttenuation[NUM_POINT];
#endif
#if NUM_DIR > 0
uniform vec3 dirDirection[NUM_DIR];
uniform vec3 dirIntensity[NUM_DIR];
#endif
#if NUM_SPOT > 0
uniform vec3 spotPosition[NUM_SPOT];
uniform vec3 spotDirection[NUM_SPOT];
uniform vec3 spotIntensity[NUM_SPOT];
uniform vec3 spotAttenuation[NUM_SPOT];
uniform vec2 spotCone[NUM_SPOT];  // cos(outer), cos(inner)
#endif
varying vec3 vWorldPos;
varying vec3 vNormal;
varying vec2 vUv;
varying vec3 vColor;

vec3 shade(vec3 L, vec3 I, vec3 N, vec3 V, vec3 kd, vec3 ks) {
  float ndl = max(dot(N, L), 0.0);
  vec3 c = kd * ndl;
#ifdef PHONG
  vec3 R = reflect(-L, N);
  c += ks * pow(max(dot(R, V), 0.0), shininess * 128.0) * step(0.0, dot(N, L));
#endif
  return I * c;
}

void main() {
  vec3 kd = diffuseColor;
  float alpha = opacity;
#ifdef USE_VERTEX_COLOR
  kd *= vColor;
#endif
#ifdef HAS_DIFFUSE_TEXTURE
  vec4 t = texture2D(diffuseTexture, vUv);
  kd *= t.rgb;
  alpha *= t.a;
#endif
#ifdef ALPHA_MASK
  if (alpha < alphaCutoff) discard;
  alpha = 1.0;
#endif
  if (alpha < 0.05) discard;
#ifdef MATTE
  gl_FragColor = vec4(kd, alpha);
  return;
#else
  vec3 ks = specularColor;
#ifdef HAS_SPECULAR_TEXTURE
  ks *= texture2D(specularTexture, vUv).rgb;
#endif
  vec3 ke = emissiveColor;
#ifdef HAS_EMISSIVE_TEXTURE
  ke *= texture2D(emissiveTexture, vUv).rgb;
#endif
  vec3 N = normalize(vNormal);
  vec3 V = normalize(cameraPosition - vWorldPos);
  vec3 color = ke + ambientIntensity * kd + sceneAmbient * kd;
#if NUM_POINT > 0
  for (int i = 0; i < NUM_POINT; i++) {
    vec3 L = pointPosition[i] - vWorldPos;
    float d = length(L);
    vec3 a = pointAttenuation[i];
    color += shade(L / d, pointIntensity[i] / (a.x + a.y * d + a.z * d * d), N, V, kd, ks);
  }
#endif
#if NUM_DIR > 0
  for (int i = 0; i < NUM_DIR; i++) color += shade(-dirDirection[i], dirIntensity[i], N, V, kd, ks);
#endif
#if NUM_SPOT > 0
  for (int i = 0; i < NUM_SPOT; i++) {
    vec3 L = spotPosition[i] - vWorldPos;
    float d = length(L);
    L /= d;
    float c = dot(-L, spotDirection[i]);
    float s = spotCone[i].y > spotCone[i].x + 1e-6 ? smoothstep(spotCone[i].x, spotCone[i].y, c) : step(spotCone[i].x, c);
    vec3 a = spotAttenuation[i];
    color += shade(L, s * spotIntensity[i] / (a.x + a.y * d + a.z * d * d), N, V, kd, ks);
  }
#endif
  gl_FragColor = vec4(color, alpha);
#endif
}`;

// Light uniforms shared by every material (updated once per frame).
export function createLightUniforms() {
  const arr = (n) => Array.from({ length: n }, () => new THREE.Vector3());
  return {
    sceneAmbient: { value: new THREE.Vector3() },
    pointPosition: { value: arr(MAX_LIGHTS) }, pointIntensity: { value: arr(MAX_LIGHTS) }, pointAttenuation: { value: arr(MAX_LIGHTS) },
    dirDirection: { value: arr(MAX_LIGHTS) }, dirIntensity: { value: arr(MAX_LIGHTS) },
    spotPosition: { value: arr(MAX_LIGHTS) }, spotDirection: { value: arr(MAX_LIGHTS) }, spotIntensity: { value: arr(MAX_LIGHTS) },
    spotAttenuation: { value: arr(MAX_LIGHTS) },
    spotCone: { value: Array.from({ length: MAX_LIGHTS }, () => new THREE.Vector2()) },
  };
}

// Fills the shared uniforms from the scene's lights; returns the counts per type.
export function updateLightUniforms(u, lights, ambient = [0, 0, 0]) {
  u.sceneAmbient.value.fromArray(ambient);
  const counts = { point: 0, directional: 0, spot: 0 };
  for (const l of lights) {
    if (!l.on || counts[l.type] >= MAX_LIGHTS) continue;
    const i = counts[l.type]++;
    const I = [l.color[0] * l.intensity, l.color[1] * l.intensity, l.color[2] * l.intensity];
    if (l.type === 'point') {
      u.pointPosition.value[i].fromArray(l.position);
      u.pointIntensity.value[i].fromArray(I);
      u.pointAttenuation.value[i].fromArray(l.attenuation);
    } else if (l.type === 'directional') {
      u.dirDirection.value[i].fromArray(l.direction);
      u.dirIntensity.value[i].fromArray(I);
    } else {
      u.spotPosition.value[i].fromArray(l.position);
      u.spotDirection.value[i].fromArray(l.direction);
      u.spotIntensity.value[i].fromArray(I);
      u.spotAttenuation.value[i].fromArray(l.attenuation);
      u.spotCone.value[i].set(Math.cos(l.cutoff), Math.cos(l.cutoff * (1 - l.softness)));
    }
  }
  return counts;
}

export function createMaterial(desc, textures, lightUniforms, counts, geometryFlags) {
  const defines = {
    NUM_POINT: counts.point, NUM_DIR: counts.directional, NUM_SPOT: counts.spot,
  };
  if (desc.model === 'matte') defines.MATTE = 1;
  if (desc.model === 'phong') defines.PHONG = 1;
  if (geometryFlags.uv) defines.HAS_UV = 1;
  if (geometryFlags.color && desc.useVertexColor) { defines.HAS_COLOR = 1; defines.USE_VERTEX_COLOR = 1; }
  const tex = (id, name) => {
    const t = id && geometryFlags.uv ? textures(id) : null;
    if (t) defines[name] = 1;
    return { value: t };
  };
  let opacity = desc.opacity;
  if (desc.refractionCoefficient > 0) opacity *= 1 - 0.7 * desc.refractionCoefficient;
  if (desc.alphaMask) defines.ALPHA_MASK = 1;
  const uniforms = {
    ...lightUniforms,
    diffuseColor: { value: new THREE.Vector3(...desc.diffuseColor) },
    specularColor: { value: new THREE.Vector3(...desc.specularColor) },
    emissiveColor: { value: new THREE.Vector3(...desc.emissiveColor) },
    shininess: { value: desc.shininess },
    ambientIntensity: { value: desc.ambientIntensity },
    opacity: { value: opacity },
    alphaCutoff: { value: desc.alphaCutoff },
    diffuseTexture: tex(desc.diffuseTexture, 'HAS_DIFFUSE_TEXTURE'),
    specularTexture: tex(desc.specularTexture, 'HAS_SPECULAR_TEXTURE'),
    emissiveTexture: tex(desc.emissiveTexture, 'HAS_EMISSIVE_TEXTURE'),
  };
  const transparent = opacity < 1 && !desc.alphaMask;
  return new THREE.ShaderMaterial({
    vertexShader, fragmentShader, uniforms, defines,
    side: THREE.DoubleSide,  // XML3D: no face culling by default
    transparent, depthWrite: !transparent,
    vertexColors: !!defines.HAS_COLOR,  // three declares the color attribute
  });
}
