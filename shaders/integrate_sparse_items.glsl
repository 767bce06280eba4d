// Pass 1 for the smooth weighting schemes, technique 'sort', step 1: one item per (light-map
// texel t, slot s), i = t * SLOTS + s. The texel's rotated direction p = R d picks the texel of
// the weight texture it falls in (nearest; concentric map for HEMI_UPPER, octahedral otherwise);
// slot s there holds a light and a weight (the weights of a texel sum to 1). Item i gets that
// light as its cell and power x weight as its power. A texel outside the hemisphere puts its
// power in slot 0's item, cell N_LIGHTS (dropped); padded slots and a dropped texel's other
// slots go to the void cell N_LIGHTS + 1 with no power (never summed). integrate_sort.glsl and
// integrate_segment_sum.glsl then sum the items per cell, deterministically.
// Defines: N_LIGHTS, CELL_RES (weight texture side), SLOTS, HEMI_UPPER / HEMI_AXIS / neither.
#if defined COMPUTE_SHADER
layout(local_size_x = 64) in;
#include "sphere_maps.glsl"
layout(std430, binding = 1) readonly buffer TexelDirs { double tdir[]; };   // 3 per texel
layout(std430, binding = 2) readonly buffer TexelPower { vec4 tpow[]; };    // radiance x solid angle
layout(std430, binding = 3) readonly buffer SlotIndex { int sidx[]; };      // CELL_RES^2 x SLOTS
layout(std430, binding = 4) readonly buffer SlotWeight { float swt[]; };    // CELL_RES^2 x SLOTS
layout(std430, binding = 5) writeonly buffer CellIds { int cell_id[]; };    // per item
layout(std430, binding = 9) writeonly buffer ItemPower { vec4 ipow[]; };    // per item
uniform dmat3 R;
uniform uint n_texels;
#include "hemisphere_texel.glsl"
void main() {
    uint t = gl_GlobalInvocationID.x;
    if (t >= n_texels) return;
    uint base = t * uint(SLOTS);
    dvec3 d = dvec3(tdir[3u * t], tdir[3u * t + 1u], tdir[3u * t + 2u]);
    int texel = hemisphere_texel(R * d);
    vec4 pw = tpow[t];
    if (texel < 0) {
        cell_id[base] = N_LIGHTS;
        ipow[base] = vec4(pw.rgb, 0.0);
        for (int s = 1; s < SLOTS; ++s) { cell_id[base + uint(s)] = N_LIGHTS + 1; ipow[base + uint(s)] = vec4(0.0); }
        return;
    }
    int k = texel * SLOTS;
    for (int s = 0; s < SLOTS; ++s) {
        int c = sidx[k + s];
        cell_id[base + uint(s)] = c < 0 ? N_LIGHTS + 1 : c;
        ipow[base + uint(s)] = c < 0 ? vec4(0.0) : vec4(pw.rgb * swt[k + s], 0.0);
    }
}
#endif
