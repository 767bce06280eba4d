// Pass 1, technique (b): workgroup g sums texels [g C, (g + 1) C) into shared-memory bins with
// float atomics (GL_NV_shader_atomic_float), then writes its N_LIGHTS + 1 bins to
// partial[g * (N_LIGHTS + 1) + c]; integrate_reduce.glsl sums the groups in a fixed order.
// GLOBAL_BINS: bins do not fit shared memory; atomics go straight to partial (cleared first).
#if defined COMPUTE_SHADER
#extension GL_NV_shader_atomic_float : require
layout(local_size_x = 64) in;
#include "cell_lookup.glsl"
layout(std430, binding = 5) buffer Partial { vec4 partial[]; };
layout(std430, binding = 6) buffer Stats { vec4 dropped_power; uint dropped_count; };
uniform uint chunk;  // texels per workgroup
const int NB = N_LIGHTS + 1;
#if !defined GLOBAL_BINS
shared float bins[3 * NB];
#endif
void main() {
    uint g = gl_WorkGroupID.x;
    uint row = g * uint(NB);
#if !defined GLOBAL_BINS
    for (int c = int(gl_LocalInvocationIndex); c < 3 * NB; c += 64) bins[c] = 0.0;
    barrier();
#endif
    uint t0 = g * chunk;
    uint t1 = min(t0 + chunk, n_texels);
    uint dropped = 0u;
    for (uint t = t0 + gl_LocalInvocationIndex; t < t1; t += 64u) {
        int c = cell_of_texel(t);
        vec3 w = tpow[t].rgb;
        if (c == DROP_BIN) dropped += 1u;
#if defined GLOBAL_BINS
        atomicAdd(partial[row + uint(c)].r, w.r);
        atomicAdd(partial[row + uint(c)].g, w.g);
        atomicAdd(partial[row + uint(c)].b, w.b);
#else
        atomicAdd(bins[3 * c], w.r);
        atomicAdd(bins[3 * c + 1], w.g);
        atomicAdd(bins[3 * c + 2], w.b);
#endif
    }
    if (dropped > 0u) atomicAdd(dropped_count, dropped);  // integer: order-independent
#if !defined GLOBAL_BINS
    barrier();
    for (int c = int(gl_LocalInvocationIndex); c < NB; c += 64)
        partial[row + uint(c)] = vec4(bins[3 * c], bins[3 * c + 1], bins[3 * c + 2], 0.0);
#endif
}
#endif
