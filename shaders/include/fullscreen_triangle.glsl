// One triangle that covers the viewport (vertices 0, 1, 2 from gl_VertexID, no vertex buffer):
// the vertex stage of the full-screen passes (weighted_sum_frag.glsl, gui_copy.glsl).
void main() {
    vec2 v = vec2(float((gl_VertexID << 1) & 2), float(gl_VertexID & 2));
    gl_Position = vec4(v * 2.0 - 1.0, 0.0, 1.0);
}
