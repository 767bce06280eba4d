// Pass 1, final step of techniques (a) and (b): weight of cell c = sum over S slices/groups of
// partial[s][c], in a fixed order (64 strided compensated chains, then a fixed tree), so the
// result does not depend on scheduling. One workgroup per cell; cell N_LIGHTS is the dropped
// bin, written to Stats. SOURCE_TEXTURE: partials in the RGBA32F target of integrate_blend
// (alpha = texel count); otherwise in the Partial buffer of integrate_atomic.
#if defined COMPUTE_SHADER
layout(local_size_x = 64) in;
layout(std430, binding = 0) writeonly buffer Weights { vec4 w[]; };
layout(std430, binding = 6) buffer Stats { vec4 dropped_power; uint dropped_count; };
uniform int n_slices;
#if defined SOURCE_TEXTURE
uniform sampler2D partials;
uniform ivec2 grid;  // TW, TH
#else
layout(std430, binding = 5) readonly buffer Partial { vec4 partial[]; };
#endif
shared vec4 acc[64];
void main() {
    int c = int(gl_WorkGroupID.x);
    int i = int(gl_LocalInvocationIndex);
    precise vec4 sum = vec4(0.0);
    precise vec4 comp = vec4(0.0);  // Kahan compensation
    for (int s = i; s < n_slices; s += 64) {
#if defined SOURCE_TEXTURE
        vec4 x = texelFetch(partials, ivec2(c % grid.x, c / grid.x + s * grid.y), 0);
#else
        vec4 x = partial[s * (N_LIGHTS + 1) + c];
#endif
        precise vec4 y = x - comp;
        precise vec4 t = sum + y;
        comp = (t - sum) - y;
        sum = t;
    }
    acc[i] = sum;
    barrier();
    for (int h = 32; h > 0; h >>= 1) {
        if (i < h) acc[i] = acc[i] + acc[i + h];
        barrier();
    }
    if (i == 0) {
        if (c < N_LIGHTS) {
            w[c] = vec4(acc[0].rgb, 0.0);
        } else {
            dropped_power = vec4(acc[0].rgb, 0.0);
#if defined SOURCE_TEXTURE
            dropped_count = uint(acc[0].a);
#endif
        }
    }
}
#endif
