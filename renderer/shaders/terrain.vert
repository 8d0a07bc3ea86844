// Geometry clipmap vertices (Losasso & Hoppe 2004; GPU Gems 2, ch. 2): one
// (N+1)^2 grid of integer vertex indices drawn once per ring level, each
// vertex's height fetched from the height clip stack. Positions are built
// from integers relative to the camera's integer sample, so a vertex shared
// by two levels gets bit-identical coordinates from both (no crack), and a
// camera near the far corner of a 2^26-sample terrain keeps full precision.
//
// Transition: in the outer uTransition cells of a ring a vertex moves from
// its own level's height towards the coarser level's surface, reaching it
// exactly on the ring's outer edge, where the coarser ring takes over.
//
// terrain_heights.glsl (heightAt(), normalAt() and their uniforms) comes first.
layout(location = 0) in ivec2 aGrid;  // vertex index in the ring, 0..N
// The grid drawn: a ring's, set once for its draw (the attribute's current
// value), or a quadtree node's, one instance each (terrain_gl.h,
// TerrainGridOrigin).
layout(location = 1) in ivec4 aOrigin;  // xy: origin in this level's samples (even for a ring);
                                        // zw: origin in level-0 samples minus the camera's integer sample
layout(location = 2) in int aLevel;     // this grid's height level

uniform int uN;                   // cells per ring side
uniform int uCoarsest;            // no transition on the coarsest ring
uniform int uTransition;          // cells of the transition band
uniform vec2 uCamFrac;            // camera position minus its integer sample (level-0 samples)
uniform float uCamY;              // camera height in world units
uniform mat4 uViewProj;           // camera-relative view-projection
uniform vec4 uImageRel;           // colour image relative to the camera: x0, z0, x1, z1

// Ground outside the colour image is clipped here rather than discarded
// per fragment: a shader that may discard loses the early depth test, and
// hidden slopes would be shaded in full (llvmpipe pays for every one).
out float gl_ClipDistance[4];

out vec2 vRel;      // camera-relative ground position, world units (x, z)
out vec3 vNormal;   // world-space normal
out float vMorph;   // transition weight (overlay)
out float vHeight;  // height in the store's units after the transition (tests)
out float vRelY;    // camera-relative height, world units (position pass)

// The coarser level's surface at this level's sample s: its own samples at
// even s, the mean of the two ends along an odd axis, and the mean of the
// cell diagonal (the coarse cells' triangulation) when both are odd.
float coarseAt(int level, ivec2 s) {
  ivec2 c0 = s >> 1;
  ivec2 c1 = (s + 1) >> 1;
  return 0.5 * (heightAt(level + 1, c0) + heightAt(level + 1, c1));
}

void main() {
  int level = aLevel;
  ivec2 s = aOrigin.xy + aGrid;  // this level's sample
  float h = heightAt(level, s);
  float spacing = float(1 << level);
  vec3 n = normalAt(level, s, spacing);
  float alpha = 0.0;
  if (level < uCoarsest) {
    // Distance from the ring's centre in cells; alpha is 1 on the outer
    // edge and one cell in, 0 inside the transition band.
    ivec2 d = abs(2 * aGrid - uN);  // twice the distance
    float dist = 0.5 * float(max(d.x, d.y));
    float w = float(uTransition);
    alpha = clamp((dist - (0.5 * float(uN) - w - 1.0)) / w, 0.0, 1.0);
    if (alpha > 0.0) {
      h = mix(h, coarseAt(level, s), alpha);
      n = normalize(mix(n, normalAt(level + 1, s >> 1, 2.0 * spacing), alpha));
    }
  }
  // Integer offset from the camera's sample (exact), then the fraction.
  vec2 rel_samples = vec2(aOrigin.zw + aGrid * (1 << level)) - uCamFrac;
  vRel = rel_samples * uWorldPerSample;
  vNormal = n;
  vMorph = alpha;
  vHeight = h;
  float y = h * uWorldPerHeight - uCamY;
  vRelY = y;
  gl_Position = uViewProj * vec4(vRel.x, y, vRel.y, 1.0);
  gl_ClipDistance[0] = vRel.x - uImageRel.x;
  gl_ClipDistance[1] = vRel.y - uImageRel.y;
  gl_ClipDistance[2] = uImageRel.z - vRel.x;
  gl_ClipDistance[3] = uImageRel.w - vRel.y;
}
