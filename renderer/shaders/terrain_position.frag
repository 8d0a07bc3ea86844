// Position pass of the terrain (TerrainRenderer::readPositions): the
// camera-relative world position each pixel shows, for measuring the
// geometric error against the full-resolution surface. w >= 1 marks
// terrain: 1 plus the transition weight (0 outside the transition bands,
// where the shading normal is the ring's own); pixels outside the colour
// image are clipped by terrain.vert, as for the colour pass.
in vec2 vRel;
in float vRelY;
in float vMorph;
layout(location = 0) out vec4 outPosition;

void main() {
  outPosition = vec4(vRel.x, vRelY, vRel.y, 1.0 + vMorph);
}
