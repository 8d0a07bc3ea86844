// The HUD's text and boxes (hud.h): vertices in window pixels, y down.
layout(location = 0) in vec2 aPixel;
layout(location = 1) in vec4 aColour;
uniform vec2 uWindowPx;
out vec4 vColour;
void main() {
  vColour = aColour;
  vec2 ndc = aPixel / uWindowPx * 2.0 - 1.0;
  gl_Position = vec4(ndc.x, -ndc.y, 0.0, 1.0);
}
