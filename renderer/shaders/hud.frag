// The HUD: each vertex's colour, blended over the frame.
in vec4 vColour;
out vec4 outColor;
void main() { outColor = vColour; }
