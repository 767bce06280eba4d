// Test-only program for shaders/include/tonemap_curves.glsl (tests/test_gpu_relight.py; not installed):
// the display value tonemap() hands to the rgba8 store, written as float so that a test sees it unconverted.
#if defined COMPUTE_SHADER
#include "tonemap_curves.glsl"

layout(local_size_x = 64) in;
layout(std430, binding = 0) readonly buffer Hdr { vec4 hdr[]; };
layout(std430, binding = 1) writeonly buffer Out { vec4 outv[]; };
uniform int n;
uniform float u_exposure_scale;
uniform int u_method;

void main() {
    uint i = gl_GlobalInvocationID.x;
    if (i >= uint(n)) return;
    outv[i] = vec4(tonemap(hdr[i].rgb, u_exposure_scale, u_method), 1.0);
}
#endif
