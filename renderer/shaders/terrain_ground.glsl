// The terrain's ground point for the clipmap fragment shader: the
// camera-relative position interpolated from the ring vertices (instead of
// ground_ray.glsl's ray-plane intersection), and Lambert + ambient light.
in vec2 vRel;
in vec3 vNormal;
in float vMorph;

uniform vec3 uSunDir;    // unit vector towards the sun (world space)

// Every fragment is on the ground: terrain.vert clips what lies outside the
// colour image, so the shader never discards (early depth test kept).
vec2 groundRel(out bool onGround) {
  onGround = true;
  return vRel;
}

vec3 shadeTerrain(vec3 albedo) {
  vec3 n = normalize(vNormal);
  float lambert = max(dot(n, uSunDir), 0.0);
  return albedo * (AMBIENT + (1.0 - AMBIENT) * lambert);
}
