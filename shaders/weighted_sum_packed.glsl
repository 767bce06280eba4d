// Pass 2, packed version: relit(p) = inv_scale * sum_i w_i * B_i(p) over one chunk of layers and
// one band of image rows of a ffls.gpu.basis.PackedBasis (pixel-major SSBO).
//
// Layout of the basis SSBO (one per chunk x band): for each pixel of the band (row-major, x
// fastest), N_BLOCKS blocks of LAYERS_PER_BLOCK layers; a block is 3 uvec4, one per channel
// (R, G, B). With PACKED_F16 a uvec4 holds 8 float16 values (word k = layers 2k, 2k+1 of the
// block in its low, high half); otherwise 4 float32 values (word k = layer k). Layers past
// N_LAYERS (padding of the last block) hold 0.
//
// Why this shape (docs/gpu.md "Pass 2"): on llvmpipe a texelFetch costs ~30 ns whatever the
// texel size and SSBO loads with per-invocation addresses are per-lane scalar loops, so the
// layout maximises bytes per load (16) and wastes none (no alpha); unpackHalf2x16 is
// scalarised there, so halves are widened with integer ops (exact for normal float16; the
// subnormal values that the per-dataset scale admits are insignificant by construction and may
// flush to zero); and the weights are read from a uniform block at compile-time-constant
// indices (the loop over blocks has a constant trip count and is unrolled), which llvmpipe
// loads once per SIMD batch instead of once per lane.
//
// IMAGE_BASIS (storage 'image', the default): the same words in an RGBA32UI texture array,
// layer 3 b + c = block b, channel c, read with imageLoad, which llvmpipe turns into one vector
// gather per load instead of the per-lane scalar loop of an SSBO load (3x less CPU time at 8
// layers, docs/gpu.md "Pass 2").
//
// Bindings: uniform block WEIGHTS_UBO_BINDING = weights of this chunk (std140 vec4[N_LAYERS],
// rgb; the same bytes as pass 1's std430 vec4 buffer), SSBO BASIS_BINDING = packed basis of
// this band (or image unit BASIS_IMAGE_UNIT = the chunk's array), image unit 0 = output
// rgba32f; with FUSED_TONEMAP image unit 1 = display rgba8 (exposure, tone curve, sRGB as
// shaders/tonemap.glsl), and with DISPLAY_ONLY as well the HDR is not stored (one chunk only: the
// Engine stores it when it is read). Dispatch (ceil(W / LOCAL_X), rows of the band, 1).
#if defined COMPUTE_SHADER
#ifndef LOCAL_X
#define LOCAL_X 64
#endif
#if !defined N_BLOCKS || !defined N_LAYERS
#error "N_BLOCKS and N_LAYERS must be defined"
#endif
#ifdef PACKED_F16
#define LAYERS_PER_BLOCK 8
#else
#define LAYERS_PER_BLOCK 4
#endif
layout(local_size_x = LOCAL_X) in;

layout(std140, binding = WEIGHTS_UBO_BINDING) uniform PackedWeights {
    vec4 w[N_LAYERS];
};
#ifdef IMAGE_BASIS
// storage 'image': layer 3 b + c of this RGBA32UI array = block b, channel c of every pixel
layout(rgba32ui, binding = BASIS_IMAGE_UNIT) readonly uniform uimage2DArray u_basis;
#define LOAD(b, c) imageLoad(u_basis, ivec3(x, row, 3 * (b) + (c)))
#else
layout(std430, binding = BASIS_BINDING) readonly buffer PackedBasis {
    uvec4 B[];
};
#define LOAD(b, c) B[base + 3 * (b) + (c)]
#endif
layout(rgba32f, binding = 0) uniform image2D u_out;
#ifdef FUSED_TONEMAP
// the display pass of the last chunk, fused (shaders/tonemap.glsl's curves): the HDR need not be read back
#include "tonemap_curves.glsl"
layout(rgba8, binding = 1) writeonly uniform image2D u_display;
uniform float u_exposure_scale;  // 2 ** exposure
uniform int u_method;            // 0 srgb, 1 reinhard, 2 aces
#endif
uniform int u_width;       // image width W
uniform int u_row0;        // first image row of this band
uniform float u_inv_scale; // 1 / per-dataset float16 scale (1 for float32)
uniform int u_accumulate;  // 0: overwrite, 1: add to what u_out holds

// Weight of layer i for channel c; 0 for padding (i >= N_LAYERS). Both arguments are constants
// after unrolling, so this folds to one uniform load.
float wc(int i, int c) {
    return i < N_LAYERS ? w[min(i, N_LAYERS - 1)][c] : 0.0;
}

vec4 weights4(int i, int c) {
    return vec4(wc(i, c), wc(i + 1, c), wc(i + 2, c), wc(i + 3, c));
}

#ifdef PACKED_F16
// Two float16 (low, high half of x) -> float32, exact for normal numbers, signed zero kept.
vec2 halves(uint x) {
    uvec2 h = uvec2(x << 16, x);
    uvec2 bits = ((h & 0x7fff0000u) >> 3) | (h & 0x80000000u);
    return uintBitsToFloat(bits) * 5.192296858534828e33;  // 2^112: float16 bias 15 -> float32 127
}

float block_dot(uvec4 q, int i, int c) {
    return dot(vec4(halves(q.x), halves(q.y)), weights4(i, c))
         + dot(vec4(halves(q.z), halves(q.w)), weights4(i + 4, c));
}
#else
float block_dot(uvec4 q, int i, int c) {
    return dot(uintBitsToFloat(q), weights4(i, c));
}
#endif

void main() {
    int x = int(gl_GlobalInvocationID.x);
    if (x >= u_width) {
        return;
    }
    int row = int(gl_GlobalInvocationID.y);
#ifndef IMAGE_BASIS
    int base = (row * u_width + x) * (3 * N_BLOCKS);
#endif
    vec3 acc = vec3(0.0);
    for (int b = 0; b < N_BLOCKS; ++b) {  // constant trip count: unrolled
        int i = b * LAYERS_PER_BLOCK;
        acc.r += block_dot(LOAD(b, 0), i, 0);
        acc.g += block_dot(LOAD(b, 1), i, 1);
        acc.b += block_dot(LOAD(b, 2), i, 2);
    }
    acc *= u_inv_scale;
    ivec2 p = ivec2(x, u_row0 + row);
    if (u_accumulate != 0) {
        acc += imageLoad(u_out, p).rgb;
    }
#ifndef DISPLAY_ONLY
    imageStore(u_out, p, vec4(acc, 1.0));
#endif
#ifdef FUSED_TONEMAP
    imageStore(u_display, p, vec4(tonemap(acc, u_exposure_scale, u_method), 1.0));
#endif
}
#endif
