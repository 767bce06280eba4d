// Pass 1, technique (c), step 1: the cell of every texel (cell N_LIGHTS = dropped).
#if defined COMPUTE_SHADER
layout(local_size_x = 64) in;
#include "cell_lookup.glsl"
layout(std430, binding = 5) writeonly buffer CellIds { int cell_id[]; };
void main() {
    uint t = gl_GlobalInvocationID.x;
    if (t < n_texels) cell_id[t] = cell_of_texel(t);
}
#endif
