// Pass 2, compute version: relit(p) = inv_scale * sum_i w_i * B_i(p) over one texture array.
// A basis split into several arrays is summed by one dispatch per array with u_accumulate = 1
// after the first (the caller puts a memory barrier between dispatches).
// Bindings: texture unit 0 = basis array (sampler2DArray), image unit 0 = output rgba32f,
// SSBO WEIGHTS_BINDING = weights (include/weights_ssbo.glsl).
#if defined COMPUTE_SHADER
#ifndef LOCAL_X
#define LOCAL_X 8
#define LOCAL_Y 8
#endif
layout(local_size_x = LOCAL_X, local_size_y = LOCAL_Y) in;
#include "weights_ssbo.glsl"

uniform sampler2DArray u_basis;
layout(rgba32f, binding = 0) uniform image2D u_out;
uniform ivec2 u_size;
uniform int u_offset;      // index of this array's first layer in the weights
uniform int u_count;       // layers in this array
uniform float u_inv_scale; // 1 / per-dataset float16 scale
uniform int u_accumulate;  // 0: overwrite, 1: add to what u_out holds

void main() {
    ivec2 p = ivec2(gl_GlobalInvocationID.xy);
    if (p.x >= u_size.x || p.y >= u_size.y) {
        return;
    }
    vec3 acc = weighted_sum(u_basis, p, u_offset, u_count) * u_inv_scale;
    if (u_accumulate != 0) {
        acc += imageLoad(u_out, p).rgb;
    }
    imageStore(u_out, p, vec4(acc, 1.0));
}
#endif
