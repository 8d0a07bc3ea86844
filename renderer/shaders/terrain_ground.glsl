// The terrain's ground point for the clipmap fragment shader: the
// camera-relative position interpolated from the ring vertices (instead of
// ground_ray.glsl's ray-plane intersection); its normal, the vertices' or
// (PIXEL_LIGHTING) that of the heights under the pixel (terrain_heights.glsl,
// which comes first); (DETAIL) the detail textures where the colour is
// magnified; and Lambert + ambient light.
in vec2 vRel;
in vec3 vNormal;
in float vMorph;

uniform vec3 uSunDir;    // unit vector towards the sun (world space)
#ifdef PIXEL_LIGHTING
uniform vec2 uCamFrac;   // the camera's level-0 sample, fractional part (terrain.vert's)
#endif

// Every fragment is on the ground: terrain.vert clips what lies outside the
// colour image, so the shader never discards (early depth test kept).
vec2 groundRel(out bool onGround) {
  onGround = true;
  return vRel;
}

// `gx`, `gy`: the screen derivatives of the ground position (world units).
vec3 terrainNormal(vec2 gx, vec2 gy) {
#ifdef PIXEL_LIGHTING
  vec2 rel = vRel / uWorldPerSample + uCamFrac;
  float footprint = max(length(gx / uWorldPerSample), length(gy / uWorldPerSample));
  return pixelNormal(rel, footprint, normalize(vNormal));
#else
  return normalize(vNormal);
#endif
}

#ifdef DETAIL
in float vHeight;              // store units (terrain.vert)
uniform sampler2D uDetail;     // RGBA8, a material a channel: grass, soil, rock, snow; 0.5 = no change
uniform vec2 uDetailOrigin;    // the camera's ground position modulo uDetailPeriod (world units)
uniform float uDetailPeriod;   // world units one repeat of uDetail spans
uniform vec2 uHeightRange;     // the DEM's lowest and highest height (store units)

// How much of the detail a pixel gets at `magnification` (log2 of the size
// in pixels of a texel of the colour level it is drawn from): none up to a
// texel a pixel, all from 2^DETAIL_FADE_LEVELS pixels a texel, linear in
// between (continuous at both ends: no seam where the fade begins or ends).
float detailWeight(float magnification) { return clamp(magnification / DETAIL_FADE_LEVELS, 0.0, 1.0); }

// The materials' shares (grass, soil, rock, snow) by rules on the slope
// (rise over run, from the normal) and the height within the DEM's range:
// rock on slopes steeper than about 25-40 degrees, snow on the top 15 %,
// grass on the lower half, soil between; smooth steps, summing to 1.
vec4 materialWeights(vec3 n, float height) {
  float slope = length(n.xz) / max(n.y, 1e-3);
  float h = clamp((height - uHeightRange.x) / max(uHeightRange.y - uHeightRange.x, 1e-6), 0.0, 1.0);
  float rock = smoothstep(0.45, 0.85, slope);
  float snow = (1.0 - rock) * smoothstep(0.8, 0.9, h);
  float grass = (1.0 - rock - snow) * (1.0 - smoothstep(0.35, 0.6, h));
  return vec4(grass, 1.0 - rock - snow - grass, rock, snow);
}

// The colour with the detail of its materials at the pixel's magnification;
// `gx`, `gy` as terrainNormal()'s (the texture's derivatives, taken before
// the branch).
vec3 addDetail(vec3 albedo, vec2 gx, vec2 gy, vec3 n, float magnification) {
  float w = detailWeight(magnification);
  if (w <= 0.0) return albedo;
  vec2 uv = (vRel + uDetailOrigin) / uDetailPeriod;
  vec4 d = textureGrad(uDetail, uv, gx / uDetailPeriod, gy / uDetailPeriod);
  return albedo * mix(1.0, 2.0 * dot(materialWeights(n, vHeight), d), w);
}
#endif

vec3 shadeTerrain(vec3 albedo, vec3 n) {
  float lambert = max(dot(n, uSunDir), 0.0);
  return albedo * (AMBIENT + (1.0 - AMBIENT) * lambert);
}
