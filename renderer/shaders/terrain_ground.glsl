// The terrain's ground point for the clipmap fragment shader: the
// camera-relative position interpolated from the ring vertices (instead of
// ground_ray.glsl's ray-plane intersection), and Lambert + ambient light,
// with the vertices' normal or (PIXEL_LIGHTING) the normal of the heights
// under the pixel (terrain_heights.glsl, which comes first).
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
vec3 shadeTerrain(vec3 albedo, vec2 gx, vec2 gy) {
#ifdef PIXEL_LIGHTING
  vec2 rel = vRel / uWorldPerSample + uCamFrac;
  float footprint = max(length(gx / uWorldPerSample), length(gy / uWorldPerSample));
  vec3 n = pixelNormal(rel, footprint, normalize(vNormal));
#else
  vec3 n = normalize(vNormal);
#endif
  float lambert = max(dot(n, uSunDir), 0.0);
  return albedo * (AMBIENT + (1.0 - AMBIENT) * lambert);
}
