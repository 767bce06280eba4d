// The viewer's relit image on the window: the RGBA8 display texture drawn into the viewport (the
// rectangle the GUI laid out), bilinear, opaque, without blending. imgui's own image draw blends
// every fragment; on llvmpipe this draw costs about 3/4 of it (viewer/app.py).
// Texture row 0 is the image's top row: it goes to the top of the viewport.
#if defined VERTEX_SHADER
out vec2 v_uv;
void main() {
    vec2 v = vec2(float((gl_VertexID << 1) & 2), float(gl_VertexID & 2));
    v_uv = vec2(v.x, 1.0 - v.y);
    gl_Position = vec4(v * 2.0 - 1.0, 0.0, 1.0);
}
#endif

#if defined FRAGMENT_SHADER
uniform sampler2D u_image;
in vec2 v_uv;
out vec4 f_color;
void main() {
    f_color = vec4(texture(u_image, v_uv).rgb, 1.0);
}
#endif
