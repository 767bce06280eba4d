// Pass 1, technique (c), steps 2-4: a stable counting sort of the texels by cell.
// The texels are cut into N_BLOCKS contiguous blocks; invocation b owns block b and walks it
// serially, so there are no atomics and the order is fixed:
//   HISTOGRAM: count[c * N_BLOCKS + b] = texels of block b in cell c (buffer cleared first);
//   SCAN:      exclusive prefix sum of count in (cell, block) order, in place (one workgroup);
//   SCATTER:   sorted[count[c * N_BLOCKS + b]++] = power of each texel, in texel order.
// After SCATTER, count[c * N_BLOCKS + N_BLOCKS - 1] is the end of cell c's segment.
#if defined COMPUTE_SHADER
layout(std430, binding = 5) readonly buffer CellIds { int cell_id[]; };
layout(std430, binding = 7) buffer Counts { uint count[]; };
uniform uint n_texels;
const uint NB = uint(N_BLOCKS);
#if defined SCAN
layout(local_size_x = 256) in;
uniform uint n_counts;  // (N_LIGHTS + 1) * N_BLOCKS
shared uint part[256];
void main() {
    uint i = gl_LocalInvocationIndex;
    uint per = (n_counts + 255u) / 256u;
    uint a = min(i * per, n_counts), b = min(a + per, n_counts);
    uint s = 0u;
    for (uint k = a; k < b; ++k) s += count[k];
    part[i] = s;
    barrier();
    if (i == 0u) {
        uint run = 0u;
        for (uint k = 0u; k < 256u; ++k) { uint x = part[k]; part[k] = run; run += x; }
    }
    barrier();
    uint run = part[i];
    for (uint k = a; k < b; ++k) { uint x = count[k]; count[k] = run; run += x; }
}
#else
layout(local_size_x = 8) in;
#if defined SCATTER
layout(std430, binding = 2) readonly buffer TexelPower { vec4 tpow[]; };
layout(std430, binding = 8) writeonly buffer Sorted { vec4 sorted_power[]; };
#endif
void main() {
    uint b = gl_GlobalInvocationID.x;
    if (b >= NB) return;
    uint per = (n_texels + NB - 1u) / NB;
    uint t0 = min(b * per, n_texels), t1 = min(t0 + per, n_texels);
    for (uint t = t0; t < t1; ++t) {
        uint k = uint(cell_id[t]) * NB + b;
#if defined SCATTER
        uint pos = count[k];
        count[k] = pos + 1u;
        sorted_power[pos] = tpow[t];
#else
        count[k] += 1u;
#endif
    }
}
#endif
#endif
