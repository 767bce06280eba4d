// Pass 1 for the smooth weighting schemes (ffls.weights.weighting.WeightTexture): one GL_POINT
// per (light-map texel, slot). integrate_sparse_texels.glsl has found, for texel t, the texel
// of the weight texture its rotated direction p = R d falls in (nearest; concentric map for
// HEMI_UPPER, octahedral otherwise), or -1 outside the hemisphere. Slot s of that texel holds a
// light index and a weight (the weights of a texel sum to 1); the point adds power x weight to
// that light's pixel of the RGBA32F target (S slices x the cells, as in integrate_blend.glsl:
// additive blending in primitive order, a fixed-order sum per pixel). A dropped texel sends its
// power once (slot 0) to the dropped bin N_LIGHTS, alpha 1 (the count); padded slots (index -1)
// are clipped away.
// Defines: N_LIGHTS, SLOTS.
#if defined VERTEX_SHADER
layout(std430, binding = 2) readonly buffer TexelPower { vec4 tpow[]; };    // radiance x solid angle
layout(std430, binding = 4) readonly buffer SlotIndex { int sidx[]; };      // CELL_RES^2 x SLOTS
layout(std430, binding = 5) readonly buffer SlotWeight { float swt[]; };    // CELL_RES^2 x SLOTS
layout(std430, binding = 7) readonly buffer WeightTexel { int wtexel[]; };  // per light-map texel
uniform uint texels_per_slice;
uniform ivec2 grid;      // TW, TH
uniform vec2 target;     // target width, height in pixels
flat out vec4 v_power;
void main() {
    uint v = uint(gl_VertexID);
    uint t = v / uint(SLOTS);
    int s = int(v % uint(SLOTS));
    int w_texel = wtexel[t];
    bool drop = w_texel < 0;
    int c = drop ? (s == 0 ? N_LIGHTS : -1) : sidx[w_texel * SLOTS + s];
    float w = drop ? 1.0 : swt[w_texel * SLOTS + s];
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
