// Position pass of the terrain (TerrainRenderer::readPositions): the
// camera-relative world position each pixel shows, for measuring the
// geometric error against the full-resolution surface. w >= 1 marks
// terrain: 1 plus the transition weight (0 outside the transition bands,
// where the shading normal is the ring's own); pixels outside the colour
// image are left out as the colour pass does.
in vec2 vRel;
in float vRelY;
in float vMorph;
uniform vec4 uImageRel;  // texture rectangle relative to the camera: x0, z0, x1, z1
layout(location = 0) out vec4 outPosition;

void main() {
  if (vRel.x < uImageRel.x || vRel.y < uImageRel.y || vRel.x >= uImageRel.z || vRel.y >= uImageRel.w)
    discard;
  outPosition = vec4(vRel.x, vRelY, vRel.y, 1.0 + vMorph);
}
