// Pass 1 (ffls.gpu.integrate): the angular Voronoi cell of a rotated light-map texel.
// Defines (set by CellIntegrator): N_LIGHTS, CELL_RES, CELL_K, and HEMI_UPPER (concentric map,
// z < 0 dropped), HEMI_AXIS (octahedral map, p . hemi_axis < 0 dropped: a hemisphere around any
// axis) or neither (octahedral map, full sphere). Cell N_LIGHTS is the "dropped" bin.
// The decision (rotation, hemisphere test, dot products) runs in float64 so that it agrees
// with the float64 reference ffls.voronoi.integrate_weights(..., cells=...) on every texel but
// exact ties; the texel lookup runs in float32, which is safe because the candidate lists are
// conservative (a direction near a texel edge has its true cell in both texels' lists).
#include "sphere_maps.glsl"

layout(std430, binding = 1) readonly buffer TexelDirs { double tdir[]; };   // 3 per texel
layout(std430, binding = 2) readonly buffer TexelPower { vec4 tpow[]; };    // radiance x solid angle
layout(std430, binding = 3) readonly buffer LightDirs { double ldir[]; };   // 3 per light
layout(std430, binding = 4) readonly buffer Candidates { int cand[]; };     // CELL_RES^2 x CELL_K

uniform dmat3 R;           // light-map rotation: content at d moves to R d
uniform uint n_texels;     // texels in the light map
#include "hemisphere_texel.glsl"

const int DROP_BIN = N_LIGHTS;

int cell_of_texel(uint t) {
    dvec3 d = dvec3(tdir[3u * t], tdir[3u * t + 1u], tdir[3u * t + 2u]);
    dvec3 p = R * d;
    int texel = hemisphere_texel(p);
    if (texel < 0) return DROP_BIN;
    int base = texel * CELL_K;
    int best = DROP_BIN;
    double best_dot = -3.0LF;
    for (int k = 0; k < CELL_K; ++k) {
        int c = cand[base + k];
        if (c < 0) break;  // padding comes last; candidates are in increasing index order
        // the reference's operation order: (p.x l.x + p.y l.y) + p.z l.z, no fused multiply-add
        precise double dd = (p.x * ldir[3 * c] + p.y * ldir[3 * c + 1]) + p.z * ldir[3 * c + 2];
        if (dd > best_dot) { best_dot = dd; best = c; }  // strict: ties keep the lowest index
    }
    return best;
}
