// Pass 1, technique (c), step 5: the weight of cell c is the sum of its segment of the sorted
// powers, in texel order, by compensated (Kahan) chains: error <= 2 eps sum|x| per chain.
// llvmpipe ends a shader invocation's loops after 65535 iterations in all (gallivm's
// LP_MAX_TGSI_LOOP_ITERATIONS): a cell with more items (the dropped cell, or few lights over a
// large map) was summed short, silently. So two dispatches, each loop at most SEG_CHUNK long:
//   PARTIAL: invocation (c, j), j < N_CHUNKS, sums items [start + j SEG_CHUNK, ...) of cell c
//            (nothing past the cell's end) into part[c * N_CHUNKS + j];
//   FINAL:   invocation c sums its N_CHUNKS partial sums in order. Cell N_LIGHTS (dropped) goes
//            to Stats with the exact integer count.
// The order is fixed, so the result is deterministic. No shared memory or barrier (on llvmpipe
// a barrier switches every invocation's coroutine).
#if defined COMPUTE_SHADER
layout(local_size_x = 64) in;
layout(std430, binding = 7) readonly buffer Counts { uint count[]; };
layout(std430, binding = 10) buffer Partial { vec4 part[]; };
const uint NB = uint(N_BLOCKS);
const uint NC = uint(N_CHUNKS);
#if defined PARTIAL
layout(std430, binding = 8) readonly buffer Sorted { vec4 sorted_power[]; };
void main() {
    uint g = gl_GlobalInvocationID.x;
    uint c = g / NC, j = g % NC;
    if (c > uint(N_LIGHTS)) return;
    uint start = c == 0u ? 0u : count[c * NB - 1u];
    uint end = count[c * NB + NB - 1u];
    uint a = min(start + j * uint(SEG_CHUNK), end), b = min(a + uint(SEG_CHUNK), end);
    precise vec4 sum = vec4(0.0);
    precise vec4 comp = vec4(0.0);
    for (uint k = a; k < b; ++k) {
        precise vec4 y = sorted_power[k] - comp;
        precise vec4 t = sum + y;
        comp = (t - sum) - y;
        sum = t;
    }
    part[g] = sum;
}
#else
layout(std430, binding = 0) writeonly buffer Weights { vec4 w[]; };
layout(std430, binding = 6) buffer Stats { vec4 dropped_power; uint dropped_count; };
void main() {
    uint c = gl_GlobalInvocationID.x;
    if (c > uint(N_LIGHTS)) return;
    uint start = c == 0u ? 0u : count[c * NB - 1u];
    uint end = count[c * NB + NB - 1u];
    precise vec4 sum = vec4(0.0);
    precise vec4 comp = vec4(0.0);
    for (uint j = 0u; j < NC; ++j) {
        precise vec4 y = part[c * NC + j] - comp;
        precise vec4 t = sum + y;
        comp = (t - sum) - y;
        sum = t;
    }
    if (c < uint(N_LIGHTS)) w[c] = vec4(sum.rgb, 0.0);
    else { dropped_power = vec4(sum.rgb, 0.0); dropped_count = end - start; }
}
#endif
#endif
