// Compressed basis: coefficients c[k] = sum_i P[i * L + k].rgb * w[i].rgb  (k < L = K + 1;
// column 0 of P is 1, so c[0] = sum_i w_i weights the mean image). One invocation per k.
// Bindings: SSBO WEIGHTS_BINDING = weights (n vec4), 1 = P (n * L vec4), 2 = c (L vec4).
#if defined COMPUTE_SHADER
layout(local_size_x = 64) in;
#include "weights_ssbo.glsl"
layout(std430, binding = 1) readonly buffer Projection { vec4 P[]; };
layout(std430, binding = 2) writeonly buffer Coeffs { vec4 c[]; };
uniform int u_n;
uniform int u_L;

void main() {
    int k = int(gl_GlobalInvocationID.x);
    if (k >= u_L) {
        return;
    }
    vec3 acc = vec3(0.0);
    for (int i = 0; i < u_n; ++i) {
        acc += P[i * u_L + k].rgb * w[i].rgb;
    }
    c[k] = vec4(acc, 0.0);
}
#endif
