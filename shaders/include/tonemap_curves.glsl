// Tone curves matching ffls.tonemap (IEC 61966-2-1 sRGB, Reinhard 2002, Narkowicz 2016 ACES).
// method: 0 = srgb (clip), 1 = reinhard, 2 = aces. Result: sRGB-encoded display value in [0, 1].
vec3 srgb_encode(vec3 x) {
    vec3 lin = x * 12.92;
    vec3 powed = 1.055 * pow(max(x, vec3(0.0031308)), vec3(1.0 / 2.4)) - 0.055;
    return mix(powed, lin, lessThanEqual(x, vec3(0.0031308)));
}

vec3 tone_reinhard(vec3 x) {
    x = max(x, vec3(0.0));
    return x / (1.0 + x);
}

vec3 tone_aces(vec3 x) {
    x = max(x, vec3(0.0));
    return clamp((x * (2.51 * x + 0.03)) / (x * (2.43 * x + 0.59) + 0.14), 0.0, 1.0);
}

vec3 tonemap(vec3 rgb, float exposure_scale, int method) {
    vec3 x = rgb * exposure_scale;
    vec3 y;
    if (method == 1) {
        y = tone_reinhard(x);
    } else if (method == 2) {
        y = tone_aces(x);
    } else {
        y = clamp(x, 0.0, 1.0);
    }
    // An exact code value k / 255: GL lets the float -> UNORM8 conversion of an rgba8 image round
    // either way (GL 4.6, 2.3.5.2), and an NVIDIA H100 moved ~2 % of values by one code from the
    // round-to-nearest reference (docs/gpu.md, "On an NVIDIA H100"); k / 255 converts to k on any
    // conforming implementation, so every driver stores the same code values.
    return round(clamp(srgb_encode(y), 0.0, 1.0) * 255.0) / 255.0;
}
