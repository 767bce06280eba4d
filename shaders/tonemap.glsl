// Display pass: HDR rgba32f image -> exposure -> tone curve -> sRGB encode -> rgba8 image.
// Matches ffls.tonemap.tonemap(rgb, exposure, method) followed by to_uint8 within 1 code value.
// Bindings: image unit 0 = HDR input (rgba32f, read), image unit 1 = display (rgba8, write).
#if defined COMPUTE_SHADER
layout(local_size_x = 8, local_size_y = 8) in;
#include "tonemap_curves.glsl"
layout(rgba32f, binding = 0) readonly uniform image2D u_hdr;
layout(rgba8, binding = 1) writeonly uniform image2D u_display;
uniform ivec2 u_size;
uniform float u_exposure_scale;  // 2 ** exposure
uniform int u_method;            // 0 srgb, 1 reinhard, 2 aces

void main() {
    ivec2 p = ivec2(gl_GlobalInvocationID.xy);
    if (p.x >= u_size.x || p.y >= u_size.y) {
        return;
    }
    vec3 rgb = imageLoad(u_hdr, p).rgb;
    imageStore(u_display, p, vec4(tonemap(rgb, u_exposure_scale, u_method), 1.0));
}
#endif
