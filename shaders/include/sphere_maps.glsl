// GLSL twins of ffls.sphere_maps (concentric, octahedral and lat-long maps), float32.
// uv is in [0, 1]^2 with u to the right and v downward (image coordinates), exactly as in
// Python; see docs/sphere_maps.md for formulas and orientation.
#include "common.glsl"

// Concentric (Shirley-Chiu + Lambert lift) map of the upper hemisphere: zenith at the centre,
// +X to the right, +Y up (decreasing v). d need not be unit; d.z must be >= 0 (the result for
// d.z < 0 is unspecified: test the hemisphere first).
vec2 concentric_uv(vec3 d) {
    d = normalize(d);
    float r = length(d.xy) / sqrt(1.0 + max(d.z, 0.0));  // sqrt(1 - z) without cancellation
    if (r == 0.0) return vec2(0.5);
    const float q = PI / 4.0;
    float phi = atan(d.y, d.x);
    if (phi < -q) phi += 2.0 * PI;  // [-pi/4, 7pi/4)
    float a, b;
    if (phi < q) { a = r; b = r * phi / q; }
    else if (phi < 3.0 * q) { b = r; a = -r * (phi - 2.0 * q) / q; }
    else if (phi < 5.0 * q) { a = -r; b = -r * (phi - 4.0 * q) / q; }
    else { b = -r; a = r * (phi - 6.0 * q) / q; }
    return vec2(0.5 * (a + 1.0), 0.5 * (1.0 - b));
}

vec3 concentric_dir(vec2 uv) {
    float a = 2.0 * uv.x - 1.0;
    float b = 1.0 - 2.0 * uv.y;
    if (a == 0.0 && b == 0.0) return vec3(0.0, 0.0, 1.0);
    float r, phi;
    if (abs(a) > abs(b)) { r = a; phi = (PI / 4.0) * (b / a); }
    else { r = b; phi = PI / 2.0 - (PI / 4.0) * (a / b); }
    float r2 = r * r;
    return vec3(r * vec2(cos(phi), sin(phi)) * sqrt(max(2.0 - r2, 0.0)), 1.0 - r2);
}

// Clarberg's equal-area octahedral map of the full sphere: +Z at the centre, the upper
// hemisphere in the inner diamond, -Z at the corners, +X right, +Y up.
vec2 octahedral_uv(vec3 d) {
    d = normalize(d);
    float r = length(d.xy) / sqrt(1.0 + abs(d.z));  // sqrt(1 - |z|)
    float frac = r > 0.0 ? atan(abs(d.y), abs(d.x)) * (2.0 / PI) : 0.0;
    float bq = frac * r;
    float aq = r - bq;
    if (d.z < 0.0) { float t = aq; aq = 1.0 - bq; bq = 1.0 - t; }
    float a = d.x < 0.0 ? -aq : aq;
    float b = d.y < 0.0 ? -bq : bq;
    return vec2(0.5 * (a + 1.0), 0.5 * (1.0 - b));
}

vec3 octahedral_dir(vec2 uv) {
    float a = 2.0 * uv.x - 1.0;
    float b = 1.0 - 2.0 * uv.y;
    float ap = abs(a), bp = abs(b);
    float sd = 1.0 - (ap + bp);
    float r = 1.0 - abs(sd);
    float phi = (r == 0.0 ? 1.0 : (bp - ap) / r + 1.0) * (PI / 4.0);
    float z = sd < 0.0 ? r * r - 1.0 : 1.0 - r * r;
    float s = r * sqrt(max(2.0 - r * r, 0.0));
    return vec3((a < 0.0 ? -1.0 : 1.0) * cos(phi) * s, (b < 0.0 ? -1.0 : 1.0) * sin(phi) * s, z);
}

// Lat-long (Blender/Cycles): theta = pi v from +Z, phi = pi (1 - 2u) from +X toward +Y.
vec3 latlong_dir(vec2 uv) {
    float theta = PI * uv.y;
    float phi = PI * (1.0 - 2.0 * uv.x);
    return vec3(sin(theta) * cos(phi), sin(theta) * sin(phi), cos(theta));
}

vec2 latlong_uv(vec3 d) {
    float rho = length(d.xy);
    float phi = rho > 0.0 ? atan(d.y, d.x) : 0.0;
    return vec2(fract(0.5 * (1.0 - phi / PI)), atan(rho, d.z) / PI);
}
