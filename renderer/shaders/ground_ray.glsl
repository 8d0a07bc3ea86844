// Camera-relative ground point of this pixel, in level-0 texels. Computed
// from the ray rather than interpolated from vertices: its error is relative
// to its own size, so texels near the camera stay exact wherever the camera
// is in a 2^26-texel texture. The CPU reference (reference.cpp) does the
// same arithmetic in double.
uniform vec3 uForward;     // camera basis (unit vectors)
uniform vec3 uRight;
uniform vec3 uUp;
uniform vec2 uNdcScale;    // (tan(vfov/2) * aspect, tan(vfov/2))
uniform vec2 uViewportPx;
uniform float uHeight;     // camera height above the ground, texels
uniform vec4 uImageRel;    // texture rectangle relative to the camera: x0, z0, x1, z1

vec2 groundRel(out bool onGround) {
  vec2 px = vec2(gl_FragCoord.x, uViewportPx.y - gl_FragCoord.y);  // top-left origin
  vec2 ndc = vec2(2.0 * px.x / uViewportPx.x - 1.0, 1.0 - 2.0 * px.y / uViewportPx.y);
  vec3 dir = uForward + uRight * (ndc.x * uNdcScale.x) + uUp * (ndc.y * uNdcScale.y);
  float down = -dir.y;
  vec2 rel = dir.xz * (uHeight / max(down, 1e-30));
  onGround = down > 1e-12 && uHeight > 0.0 && rel.x >= uImageRel.x && rel.y >= uImageRel.y &&
             rel.x < uImageRel.z && rel.y < uImageRel.w;
  return rel;
}
