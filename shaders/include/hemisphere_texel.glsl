// The texel of the CELL_RES x CELL_RES sphere map (the cell texture, or the smooth schemes' weight
// texture) that a rotated light-map direction p falls in, as an index ij.y * CELL_RES + ij.x, or -1
// when p lies outside the covered hemisphere (the texel is dropped). Include after sphere_maps.glsl.
// Defines: CELL_RES, and HEMI_UPPER (concentric map, z < 0 dropped), HEMI_AXIS (octahedral map,
// p . hemi_axis < 0 dropped: a hemisphere around any axis) or neither (octahedral map, full sphere).
// The hemisphere test runs in float64 in the reference's operation order (Hemisphere.side:
// (p.x a.x + p.y a.y) + p.z a.z, no fused multiply-add); the lookup in float32.
#if defined HEMI_AXIS
uniform dvec3 hemi_axis;   // unit axis of the covered hemisphere (ffls.conventions.Hemisphere)
#endif

int hemisphere_texel(dvec3 p) {
#if defined HEMI_UPPER
    if (p.z < 0.0LF) return -1;
    vec2 uv = concentric_uv(vec3(p));
#else
#if defined HEMI_AXIS
    precise double side = (p.x * hemi_axis.x + p.y * hemi_axis.y) + p.z * hemi_axis.z;
    if (side < 0.0LF) return -1;
#endif
    vec2 uv = octahedral_uv(vec3(p));
#endif
    ivec2 ij = clamp(ivec2(floor(uv * float(CELL_RES))), ivec2(0), ivec2(CELL_RES - 1));
    return ij.y * CELL_RES + ij.x;
}
