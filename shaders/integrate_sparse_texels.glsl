// Pass 1 for the smooth weighting schemes, step 1: the weight-texture texel of every light-map
// texel (rotation, hemisphere test and lookup done once per texel instead of once per slot), or
// -1 for a texel outside the hemisphere (dropped). Read by integrate_sparse.glsl.
// Defines: CELL_RES (weight texture side), HEMI_UPPER / HEMI_AXIS / neither.
#if defined COMPUTE_SHADER
layout(local_size_x = 64) in;
#include "sphere_maps.glsl"
layout(std430, binding = 1) readonly buffer TexelDirs { double tdir[]; };   // 3 per texel
layout(std430, binding = 7) writeonly buffer WeightTexel { int wtexel[]; };
uniform dmat3 R;
uniform uint n_texels;
#include "hemisphere_texel.glsl"
void main() {
    uint t = gl_GlobalInvocationID.x;
    if (t >= n_texels) return;
    dvec3 d = dvec3(tdir[3u * t], tdir[3u * t + 1u], tdir[3u * t + 2u]);
    wtexel[t] = hemisphere_texel(R * d);
}
#endif
