// Pass-2 weights: std430 `vec4 w[]` (rgb used, a ignored), float32; the layout pass 1
// (ffls.gpu.integrate, `CellIntegrator.weights_buffer`) writes. Bound at WEIGHTS_BINDING
// (ffls.gpu.engine.WEIGHTS_BINDING = 0) for the dispatch/draw that reads it.
#ifndef WEIGHTS_BINDING
#define WEIGHTS_BINDING 0
#endif
layout(std430, binding = WEIGHTS_BINDING) readonly buffer Weights {
    vec4 w[];
};

// sum_{i < count} w[offset + i].rgb * basis[layer i] at texel p, float32 accumulation.
vec3 weighted_sum(sampler2DArray basis, ivec2 p, int offset, int count) {
    vec3 acc = vec3(0.0);
    for (int i = 0; i < count; ++i) {
        acc += w[offset + i].rgb * texelFetch(basis, ivec3(p, i), 0).rgb;
    }
    return acc;
}
