// Pass 1, technique (c), step 5: the weight of cell c is the sum of its segment of the sorted
// powers (texel order within the segment), by 64 strided compensated chains and a fixed tree.
// One workgroup per cell; cell N_LIGHTS (dropped) goes to Stats with the exact integer count.
#if defined COMPUTE_SHADER
layout(local_size_x = 64) in;
layout(std430, binding = 0) writeonly buffer Weights { vec4 w[]; };
layout(std430, binding = 6) buffer Stats { vec4 dropped_power; uint dropped_count; };
layout(std430, binding = 7) readonly buffer Counts { uint count[]; };
layout(std430, binding = 8) readonly buffer Sorted { vec4 sorted_power[]; };
const uint NB = uint(N_BLOCKS);
shared vec4 acc[64];
void main() {
    uint c = gl_WorkGroupID.x;
    uint i = gl_LocalInvocationIndex;
    uint start = c == 0u ? 0u : count[c * NB - 1u];
    uint end = count[c * NB + NB - 1u];
    precise vec4 sum = vec4(0.0);
    precise vec4 comp = vec4(0.0);
    for (uint k = start + i; k < end; k += 64u) {
        precise vec4 y = sorted_power[k] - comp;
        precise vec4 t = sum + y;
        comp = (t - sum) - y;
        sum = t;
    }
    acc[i] = sum;
    barrier();
    for (uint h = 32u; h > 0u; h >>= 1) {
        if (i < h) acc[i] = acc[i] + acc[i + h];
        barrier();
    }
    if (i == 0u) {
        if (c < uint(N_LIGHTS)) w[c] = vec4(acc[0].rgb, 0.0);
        else { dropped_power = vec4(acc[0].rgb, 0.0); dropped_count = end - start; }
    }
}
#endif
