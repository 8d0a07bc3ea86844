// Baseline for the benchmark: the same ground drawn from one ordinary
// mipmapped 2D texture with hardware trilinear filtering.
layout(location = 0) out vec4 outColor;
uniform sampler2D uPlain;
uniform vec2 uCamUv;      // camera position / texture size
uniform vec2 uInvSize;    // 1 / texture size in texels

void main() {
  bool onGround;
  vec2 rel = groundRel(onGround);
  vec2 uv = uCamUv + rel * uInvSize;
  vec4 color = texture(uPlain, uv);
  if (!onGround) discard;
  outColor = vec4(color.rgb, 1.0);
}
