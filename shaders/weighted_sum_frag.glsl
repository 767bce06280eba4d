// Pass 2, fragment version: a full-screen triangle into an RGBA32F framebuffer; several arrays
// are summed with additive blending (GL_ONE, GL_ONE). Same uniforms as weighted_sum.glsl.
// Framebuffer row y is image row y (no flip): gl_FragCoord indexes the basis texels directly.
#if defined VERTEX_SHADER
#include "fullscreen_triangle.glsl"
#endif

#if defined FRAGMENT_SHADER
#include "weights_ssbo.glsl"
uniform sampler2DArray u_basis;
uniform int u_offset;
uniform int u_count;
uniform float u_inv_scale;
out vec4 f_color;

void main() {
    ivec2 p = ivec2(gl_FragCoord.xy);
    f_color = vec4(weighted_sum(u_basis, p, u_offset, u_count) * u_inv_scale, 1.0);
}
#endif
