// Pass 1 for the smooth weighting schemes (ffls.weights.weighting.WeightTexture): one GL_POINT
// per (light-map texel, slot). Texel t's rotated direction p = R d picks the texel of the weight
// texture it falls in (nearest; concentric map for HEMI_UPPER, octahedral otherwise); slot s of
// that texel holds a light index and a weight (the weights of a texel sum to 1), and the point
// adds power x weight to that light's pixel of the RGBA32F target (S slices x the cells, as in
// integrate_blend.glsl: additive blending in primitive order, a fixed-order sum per pixel).
// A texel outside the hemisphere sends its power once (slot 0) to the dropped bin N_LIGHTS,
// alpha 1 (the count); padded slots (index -1) are clipped away.
// Defines: N_LIGHTS, CELL_RES (weight texture side), SLOTS, HEMI_UPPER / HEMI_AXIS / neither.
#if defined VERTEX_SHADER
#include "sphere_maps.glsl"
layout(std430, binding = 1) readonly buffer TexelDirs { double tdir[]; };   // 3 per texel
layout(std430, binding = 2) readonly buffer TexelPower { vec4 tpow[]; };    // radiance x solid angle
layout(std430, binding = 4) readonly buffer SlotIndex { int sidx[]; };      // CELL_RES^2 x SLOTS
layout(std430, binding = 5) readonly buffer SlotWeight { float swt[]; };    // CELL_RES^2 x SLOTS
uniform dmat3 R;
uniform uint texels_per_slice;
uniform ivec2 grid;      // TW, TH
uniform vec2 target;     // target width, height in pixels
#if defined HEMI_AXIS
uniform dvec3 hemi_axis;
#endif
flat out vec4 v_power;
void main() {
    uint v = uint(gl_VertexID);
    uint t = v / uint(SLOTS);
    int s = int(v % uint(SLOTS));
    dvec3 d = dvec3(tdir[3u * t], tdir[3u * t + 1u], tdir[3u * t + 2u]);
    dvec3 p = R * d;
    int c;
    float w;
    bool drop;
#if defined HEMI_UPPER
    drop = p.z < 0.0LF;
#elif defined HEMI_AXIS
    precise double side = (p.x * hemi_axis.x + p.y * hemi_axis.y) + p.z * hemi_axis.z;
    drop = side < 0.0LF;
#else
    drop = false;
#endif
    if (drop) {
        c = s == 0 ? N_LIGHTS : -1;
        w = 1.0;
    } else {
#if defined HEMI_UPPER
        vec2 uv = concentric_uv(vec3(p));
#else
        vec2 uv = octahedral_uv(vec3(p));
#endif
        ivec2 ij = clamp(ivec2(floor(uv * float(CELL_RES))), ivec2(0), ivec2(CELL_RES - 1));
        int k = (ij.y * CELL_RES + ij.x) * SLOTS + s;
        c = sidx[k];
        w = swt[k];
    }
    int slice = int(t / texels_per_slice);
    vec2 px = vec2(float(c % grid.x), float(c / grid.x + slice * grid.y)) + 0.5;
    gl_Position = c < 0 ? vec4(2.0, 2.0, 0.0, 1.0) : vec4(px / target * 2.0 - 1.0, 0.0, 1.0);
    gl_PointSize = 1.0;
    v_power = vec4(tpow[t].rgb * w, drop ? 1.0 : 0.0);
}
#elif defined FRAGMENT_SHADER
flat in vec4 v_power;
layout(location = 0) out vec4 frag;
void main() { frag = v_power; }
#endif
