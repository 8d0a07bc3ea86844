// The clipmap ground: level from screen-space derivatives of the level-0
// texel position, clamped to MaxTextureLOD and to per-tile residency (the
// usable map), trilinear across levels. Stack level L is layer L of one
// array texture, placed toroidally (GL_REPEAT does the wrap), with level
// L + 1 over the same ground in its mip 1; the pyramid level's layer holds
// the whole coarse pyramid as its mip chain. So every fragment makes one
// trilinear fetch, whatever its level: llvmpipe runs both sides of a
// divergent branch, and a second texture path cost about 2 ms per 640x360
// frame (docs/benchmarks.md).
//
// PAGED (TextureMemory::kPaged): the tiles live in a pool of pages, four
// to a layer of uStack (page p: quarter p % 4 of layer p / 4): a tile with
// a PAGE_BORDER-texel border of its neighbours' texels, and in mip 1 the
// next coarser level over it (with half that border). uUsable then covers every level and also names, per
// slot, the page of the finest usable tile over it; the fetch is the same
// single trilinear one, from that page.
layout(location = 0) out vec4 outColor;

#ifdef PAGED
uniform sampler2DArray uStack;    // the pool: 2 x 2 pages a layer
uniform usampler2DArray uUsable;  // slots^2 per level: usableCode() | levels up << 8 | page << 16
uniform int uTopLevel;            // coarsest level
// The pyramid level's tile grid, and the absolute tile of its slot cell's
// origin (uCamCell). Its tile (x, y) is always at page 4 * (1 + (y / 2) *
// uPyramidLayersX + x / 2) + the quarter of its parity (pyramidPage() in
// renderer.h), with no level up: the fallback needs no lookup.
uniform ivec2 uPyramidTiles;
uniform vec2 uPyramidOrigin;
uniform int uPyramidLayersX;
#else
uniform sampler2DArray uStack;    // layer l: level l (mip 0), l + 1 (mip 1); pyramid layer: chain
uniform usampler2DArray uUsable;  // slots^2 per stack level: usableCode() | levels up << 8
#endif
uniform int uPyramidLevel;
uniform float uMinLod;            // MaxTextureLOD from the streamer
uniform float uMaxLod;            // coarsest level
uniform int uSlots;               // slot period (tiles)
// Per level, computed in double on the CPU: xy = the camera in tiles
// relative to the slot cell it lies in (a multiple of the slot period, so
// only small numbers reach the GPU), zw = that cell's index mod 4.
uniform vec4 uCamCell[MAX_LEVELS];
uniform float uInvTileTexels[MAX_LEVELS];  // 1 / (tile_px * 2^level)
uniform float uTilePx;

vec3 levelTint(int level) {
  const vec3 k[8] = vec3[8](vec3(1, 0.2, 0.2), vec3(1, 0.6, 0.1), vec3(1, 1, 0.2), vec3(0.3, 1, 0.3),
                            vec3(0.2, 1, 1), vec3(0.3, 0.5, 1), vec3(0.7, 0.3, 1), vec3(1, 0.4, 0.8));
  return k[level & 7];
}

// Position of the ground point in level `level`'s slots (tiles, [0, slots)),
// its slot, and the code the usable map holds for it: 1 + px + 4 py with
// px, py the tile's slot period (tile / slots) mod 4 per axis (1..16), so a
// tile outside the window never passes for the one sharing its slot. Slot = tile mod slots is
// toroidalSlot() of clipmap.h; usableCode() there writes the code.
vec2 slotPosition(int level, vec2 rel, out ivec2 slot, out uint code) {
  vec4 cam = uCamCell[level];
  float slots = float(uSlots);
  vec2 tq = cam.xy + rel * uInvTileTexels[level];
  vec2 tile = floor(tq);  // relative to the cell: small, exact
  vec2 period = floor((tile + 0.5) / slots);
  vec2 s = tile - period * slots;
  slot = ivec2(s);
  vec2 p4 = mod(cam.zw + period, 4.0);
  code = 1u + uint(p4.x) + 4u * uint(p4.y);
  return s + (tq - tile);
}

void main() {
  bool onGround;
  vec2 rel = groundRel(onGround);
  // Derivatives first, while every lane of the quad is still running.
  vec2 gx = dFdx(rel);
  vec2 gy = dFdy(rel);
  if (!onGround) discard;
  float lambda = log2(max(max(length(gx), length(gy)), 1e-30));
  float lod = clamp(lambda, uMinLod, uMaxLod);
  int wanted = int(lod);
#ifdef PAGED
  // The wanted level's entry (any level: the coarse ones cover their whole
  // level); ground outside the wanted level's window falls back to the
  // pyramid level's tile, whose page is arithmetic (llvmpipe computes the
  // fallback for every fragment: a second texelFetch there cost about 5 %).
  int probe = min(wanted, uTopLevel);
  ivec2 slot;
  uint code;
  slotPosition(probe, rel, slot, code);
  uint v = texelFetch(uUsable, ivec3(slot, probe), 0).r;
  bool hit = (v & 255u) == code;
  vec2 ptq = uCamCell[uPyramidLevel].xy + rel * uInvTileTexels[uPyramidLevel];
  ivec2 pt = clamp(ivec2(floor(ptq + uPyramidOrigin)), ivec2(0), uPyramidTiles - 1);
  int pp = 4 * (1 + (pt.y >> 1) * uPyramidLayersX + (pt.x >> 1)) + (pt.x & 1) + 2 * (pt.y & 1);
  uint e = hit ? v : uint(pp) << 16;
  int level = min((hit ? probe : uPyramidLevel) + int((e >> 8) & 255u), uTopLevel);
  float used = max(lod, float(level));
  // The position in the tile, then in its page's layer (border included).
  vec2 tq = uCamCell[level].xy + rel * uInvTileTexels[level];
  uint page = e >> 16;
  float pagePx = uTilePx + 2.0 * float(PAGE_BORDER);
  vec2 quarter = vec2(float(page & 1u), float((page >> 1) & 1u)) * pagePx;
  vec2 inLayer = (quarter + float(PAGE_BORDER) + fract(tq) * uTilePx) / (2.0 * pagePx);
  vec4 color = textureLod(uStack, vec3(inLayer, float(page >> 2)), used - float(level));
#else
  // One lookup at the wanted level gives the finest usable level for this
  // spot (usable map, high byte); a tile outside the wanted level's window
  // (code mismatch) falls back to the always complete pyramid level.
  int level = uPyramidLevel;
  {
    ivec2 slot;
    uint code;
    int probe = min(wanted, max(uPyramidLevel - 1, 0));
    slotPosition(probe, rel, slot, code);
    uint v = texelFetch(uUsable, ivec3(slot, probe), 0).r;
    if (wanted < uPyramidLevel && (v & 255u) == code) level = min(wanted + int(v >> 8), uPyramidLevel);
  }
  float used = max(lod, float(level));
  // Levels past the pyramid level are mips of the pyramid layer.
  int layer = min(level, uPyramidLevel);
  // Cell-relative is enough here: GL_REPEAT wraps onto the slots.
  vec2 tq = uCamCell[layer].xy + rel * uInvTileTexels[layer];
  vec4 color = textureLod(uStack, vec3(tq / float(uSlots), float(layer)), used - float(layer));
#endif
#ifdef OVERLAY
  {
    color.rgb = mix(color.rgb, levelTint(int(used)), 0.4);
    vec2 stripe = fract((gl_FragCoord.xy) / 8.0);
    if (level > wanted && stripe.x + stripe.y > 1.0) color.rgb = vec3(1.0, 0.0, 0.0);  // missing
    if (lambda < uMinLod && uMinLod > 0.0 && stripe.x < 0.25) color.rgb = vec3(0.0, 0.0, 1.0);  // throttled
    if (level < uPyramidLevel) {
      vec2 f = fract(tq);
      if (min(min(f.x, f.y), min(1.0 - f.x, 1.0 - f.y)) * uTilePx < 1.0) color.rgb *= 0.3;
    }
  }
#endif
#ifdef TERRAIN
  vec3 normal = terrainNormal(gx, gy);
#ifdef DETAIL
  color.rgb = addDetail(color.rgb, gx, gy, normal, used - lambda);
#endif
  color.rgb = shadeTerrain(color.rgb, normal);
#ifdef OVERLAY
  color.rgb = mix(color.rgb, vec3(1.0, 0.0, 1.0), 0.5 * vMorph);  // transition bands
#endif
#endif
  // Colour is premultiplied by its alpha (a no-data pixel is black under
  // alpha 0: tiler/src/nodata_alpha.h): where the ground is not covered the
  // sky colour shows, as it does where the ray misses the texture.
  outColor = vec4(color.rgb + (1.0 - color.a) * SKY_RGB, 1.0);
}
