// Pass 1, technique (c), step 5: the weight of cell c is the sum of its segment of the sorted
// powers, in texel order, by one compensated (Kahan) chain: error <= 2 eps sum|x| whatever the
// segment's length. One invocation per cell and no shared memory or barrier (on llvmpipe a
// barrier switches every invocation's coroutine: the former one-workgroup-per-cell tree cost
// 2.6 ms of CPU for 257 cells, this 0.1 ms). Cell N_LIGHTS (dropped) goes to Stats with the
// exact integer count.
#if defined COMPUTE_SHADER
layout(local_size_x = 64) in;
layout(std430, binding = 0) writeonly buffer Weights { vec4 w[]; };
layout(std430, binding = 6) buffer Stats { vec4 dropped_power; uint dropped_count; };
layout(std430, binding = 7) readonly buffer Counts { uint count[]; };
layout(std430, binding = 8) readonly buffer Sorted { vec4 sorted_power[]; };
const uint NB = uint(N_BLOCKS);
void main() {
    uint c = gl_GlobalInvocationID.x;
    if (c > uint(N_LIGHTS)) return;
    uint start = c == 0u ? 0u : count[c * NB - 1u];
    uint end = count[c * NB + NB - 1u];
    precise vec4 sum = vec4(0.0);
    precise vec4 comp = vec4(0.0);
    for (uint k = start; k < end; ++k) {
        precise vec4 y = sorted_power[k] - comp;
        precise vec4 t = sum + y;
        comp = (t - sum) - y;
        sum = t;
    }
    if (c < uint(N_LIGHTS)) w[c] = vec4(sum.rgb, 0.0);
    else { dropped_power = vec4(sum.rgb, 0.0); dropped_count = end - start; }
}
#endif
