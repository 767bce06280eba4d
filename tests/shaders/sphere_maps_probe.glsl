// Test-only program for shaders/include/sphere_maps.glsl (tests/test_sphere_maps.py; not installed): evaluates
// every map function on n directions and n uv points.
#if defined COMPUTE_SHADER
#include "sphere_maps.glsl"

layout(local_size_x = 64) in;
layout(std430, binding = 0) readonly buffer Dirs { vec4 dirs[]; };
layout(std430, binding = 1) readonly buffer UVs { vec2 uvs[]; };
layout(std430, binding = 2) writeonly buffer Out { vec4 outv[]; };  // 5 vec4 per item
uniform int n;

void main() {
    uint i = gl_GlobalInvocationID.x;
    if (i >= uint(n)) return;
    vec3 d = dirs[i].xyz;
    vec2 uv = uvs[i];
    outv[5u * i + 0u] = vec4(concentric_uv(d), octahedral_uv(d));
    outv[5u * i + 1u] = vec4(latlong_uv(d), 0.0, 0.0);
    outv[5u * i + 2u] = vec4(concentric_dir(uv), 0.0);
    outv[5u * i + 3u] = vec4(octahedral_dir(uv), 0.0);
    outv[5u * i + 4u] = vec4(latlong_dir(uv), 0.0);
}
#endif
