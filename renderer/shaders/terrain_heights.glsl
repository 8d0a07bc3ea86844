// The height clip stack for terrain.vert and the per-pixel lighting of the
// terrain's fragment shader: one height sample of a level, the normal of
// its central differences, and (PIXEL_LIGHTING) the normal under a pixel
// from the finest resident level its footprint allows.
uniform sampler2DArray uHeights;  // R32F, layer l = height level l, toroidal (period uHeightPeriod)
uniform ivec2 uLevelSize[MAX_LEVELS];  // samples of each stored height level
uniform int uStoredLevels;        // levels in the height pyramid; coarser rings decimate the last
uniform int uHeightPeriod;        // texels per stack layer side (toroidal period)
// WHOLE_LEVEL0: the full-resolution mesh's stack holds level 0 alone
// (whole, no wrap); level L's sample k is then level-0 sample k 2^L (the
// pyramid decimates). A define, not a uniform: a software rasterizer runs
// both sides of a branch on a uniform.
uniform vec2 uWorldPerSample;     // world units (level-0 colour texels) per level-0 sample, x and z
uniform float uWorldPerHeight;    // world units per height unit (vertical scale included)

float heightAt(int level, ivec2 s) {
  if (level >= uStoredLevels) {
    // A ring coarser than the pyramid's last level (one tile): its samples
    // are every 2^k-th sample of that level, as decimation would make them.
    s = s << (level - uStoredLevels + 1);
    level = uStoredLevels - 1;
  }
  ivec2 size = uLevelSize[level];
  s = clamp(s, ivec2(0), size - 1);
#ifdef WHOLE_LEVEL0
  s = s << level;
  level = 0;
#endif
  ivec2 t = s - uHeightPeriod * (s / uHeightPeriod);  // s >= 0: plain remainder
  return texelFetch(uHeights, ivec3(t, level), 0).r;
}

// Height differences across sample s (two samples apart), x and z.
vec2 gradientAt(int level, ivec2 s) {
  float dx = heightAt(level, s + ivec2(1, 0)) - heightAt(level, s - ivec2(1, 0));
  float dz = heightAt(level, s + ivec2(0, 1)) - heightAt(level, s - ivec2(0, 1));
  return vec2(dx, dz);
}

// The world-space slope (rise over run, x and z) of gradient d at a level
// whose samples lie `spacing` level-0 samples apart, and its normal.
vec2 gradientSlope(vec2 d, float spacing) {
  // Central differences in world units: heights scaled, distances 2 samples.
  return d * uWorldPerHeight / (2.0 * spacing * uWorldPerSample);
}
vec3 slopeNormal(vec2 slope) { return normalize(vec3(-slope.x, 1.0, -slope.y)); }

vec3 normalAt(int level, ivec2 s, float spacing) { return slopeNormal(gradientSlope(gradientAt(level, s), spacing)); }

#ifdef PIXEL_LIGHTING
// Per level: the samples (first x, y, last x, y) whose tiles are held
// around the camera (TerrainHeightStack::residentSamples()).
uniform ivec4 uResidentSamples[MAX_LEVELS];
// Per level: where uCamSample >> level lies in the layer (mod uHeightPeriod).
uniform ivec2 uCamTexel[MAX_LEVELS];
// RG32F, laid out as uHeights, filtered bilinearly: gradientAt() of each
// sample, stored on upload; kNoGradient where a neighbour's tile is not
// resident (TerrainHeightStack::gradientsTexture()).
uniform sampler2DArray uGradients;
uniform ivec2 uCamSample;              // the camera's level-0 sample (integer part)
const float kNoGradientAbove = 1e20;   // a filtered sentinel (1e30) is above this

// The level's cell under the point `rel` level-0 samples from uCamSample:
// its first sample, and the point's fraction across it. The camera's
// sample is split so that only small numbers meet floats.
void levelCell(int level, vec2 rel, out ivec2 cell, out vec2 frac_in) {
  ivec2 high = uCamSample >> level;
  vec2 low = (vec2(uCamSample - (high << level)) + rel) * exp2(-float(level));
  vec2 whole = floor(low);
  cell = high + ivec2(whole);
  frac_in = low - whole;
}

// The gradient at fraction f of the level's cell, bilinear between its
// corners' gradientAt(), the level's edge clamped as heightAt() clamps it
// (across the edge the component along it falls to 0 over one cell).
// False when the heights it needs are not resident.
bool cellGradient(int level, ivec2 cell, vec2 f, out vec2 g) {
#ifdef WHOLE_LEVEL0
  // The reference: every gradient from level 0, blended here.
  vec2 g0 = mix(gradientAt(level, cell), gradientAt(level, cell + ivec2(1, 0)), f.x);
  vec2 g1 = mix(gradientAt(level, cell + ivec2(0, 1)), gradientAt(level, cell + ivec2(1, 1)), f.x);
  g = mix(g0, g1, f.y);
  return true;
#else
  // The heights the four corners' gradients read: held (a block test, no
  // lookup: a software rasterizer pays for every fetch).
  ivec4 held = uResidentSamples[level];
  if (any(lessThan(cell - 1, held.xy)) || any(greaterThan(cell + 2, held.zw))) return false;
  ivec2 size = uLevelSize[level];
  ivec2 c = clamp(cell, ivec2(0), size - 1);
  // Inside the level the hardware blends the four corners (their tiles
  // lie in the neighbouring slots, wrapped by GL_REPEAT); on and beyond
  // the edge it reads the edge sample and ramps the crossing component
  // down. The texel from the camera's: small whole numbers, so a float
  // remainder is exact and, unlike an integer division, vectorised by
  // software rasterizers.
  bvec2 inside = bvec2(cell.x >= 0 && cell.x < size.x - 1, cell.y >= 0 && cell.y < size.y - 1);
  float period = float(uHeightPeriod);
  vec2 t = vec2(uCamTexel[level] + (c - (uCamSample >> level)));
  t -= period * floor((t + 0.5) / period);
  vec2 texel = t + mix(vec2(0.0), f, inside) + 0.5;
  g = textureLod(uGradients, vec3(texel / period, float(level)), 0.0).rg;
  if (!(abs(g.x) < kNoGradientAbove)) return false;
  // 1 - f on the last cell, f on the one before the first, 0 further out.
  g *= clamp(min(vec2(size - cell) - f, vec2(cell + 1) + f), 0.0, 1.0);
  return true;
#endif
}

// The normal under a pixel at `rel` (level-0 samples from uCamSample) whose
// footprint spans `footprint` level-0 samples: the slope of the
// footprint's level (as the colour's level) blended with the next coarser
// level's by the fraction, each from its own heights; where a level's
// tiles are not resident the next coarser one is used; `fallback` (the
// vertices') when even the coarsest is not.
vec3 pixelNormal(vec2 rel, float footprint, vec3 fallback) {
  int last = uStoredLevels - 1;
  float lod = clamp(log2(max(footprint, 1e-30)), 0.0, float(last));
  int level = int(lod);
  float t = lod - float(level);
  ivec2 cell;
  vec2 f, g;
  levelCell(level, rel, cell, f);
  while (!cellGradient(level, cell, f, g)) {
    // Rare (the coarse levels are whole in the stack): further up.
    if (level >= last) return fallback;
    ++level;
    t = 0.0;
    levelCell(level, rel, cell, f);
  }
  vec2 slope = gradientSlope(g, exp2(float(level)));
  if (t > 0.0 && level < last) {
    levelCell(level + 1, rel, cell, f);
    if (cellGradient(level + 1, cell, f, g)) slope = mix(slope, gradientSlope(g, exp2(float(level + 1))), t);
  }
  return slopeNormal(slope);
}
#endif
