// The viewer's cached control panel on the window: texel for pixel, opaque, without blending.
// The panel texture is the size of the window's framebuffer, so gl_FragCoord addresses it directly;
// the viewport (the panel's rectangle) limits the copy (viewer/gui_cache.py).
#if defined VERTEX_SHADER
#include "fullscreen_triangle.glsl"
#endif

#if defined FRAGMENT_SHADER
uniform sampler2D u_panel;
out vec4 f_color;
void main() {
    f_color = vec4(texelFetch(u_panel, ivec2(gl_FragCoord.xy), 0).rgb, 1.0);
}
#endif
