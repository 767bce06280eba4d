// Pass 1, technique (a): one GL_POINT per light-map texel, additively blended into an
// RGBA32F target laid out as S slices (stacked vertically) of a TW x TH grid of cells.
// Texel t goes to slice t / texels_per_slice. Blending happens in primitive order (GL 4.5
// section 14.1 / 17.3: per-fragment operations follow primitive order), so every pixel is the
// float32 sum of its texels in increasing texel order: deterministic. Alpha counts texels.
#if defined VERTEX_SHADER
#include "cell_lookup.glsl"
uniform uint texels_per_slice;
uniform ivec2 grid;      // TW, TH
uniform vec2 target;     // target width, height in pixels
flat out vec4 v_power;
void main() {
    uint t = uint(gl_VertexID);
    int c = cell_of_texel(t);
    int s = int(t / texels_per_slice);
    vec2 px = vec2(float(c % grid.x), float(c / grid.x + s * grid.y)) + 0.5;
    gl_Position = vec4(px / target * 2.0 - 1.0, 0.0, 1.0);
    gl_PointSize = 1.0;
    v_power = vec4(tpow[t].rgb, 1.0);
}
#elif defined FRAGMENT_SHADER
flat in vec4 v_power;
layout(location = 0) out vec4 frag;
void main() { frag = v_power; }
#endif
