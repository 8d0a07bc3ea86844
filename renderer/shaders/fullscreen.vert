// One triangle covering the viewport; the ground is found per pixel by
// intersecting the view ray with y = 0 in the fragment shader, so no vertex
// ever carries a large world coordinate (see docs/renderer.md, precision).
void main() {
  vec2 p = vec2(float((gl_VertexID << 1) & 2), float(gl_VertexID & 2));
  gl_Position = vec4(p * 2.0 - 1.0, 0.0, 1.0);
}
