// microfacet viewer: vertex shader. Attributes: world position, uv, tangent s and normal n
// (t = n x s completes the local frame: local z = macro normal). u_patch maps the uv square
// onto the whole viewport (the top-down validation view, one pixel per texel of a level).
in vec3 a_position;
in vec2 a_uv;
in vec3 a_tangent;
in vec3 a_normal;
uniform mat4 u_view_projection;
uniform bool u_patch;
out vec3 v_world;
out vec2 v_uv;
out vec3 v_tangent;
out vec3 v_normal;

void main() {
    v_world = a_position;
    v_uv = a_uv;
    v_tangent = a_tangent;
    v_normal = a_normal;
    gl_Position = u_patch ? vec4(2.0 * a_uv.x - 1.0, 1.0 - 2.0 * a_uv.y, 0.0, 1.0)
                          : u_view_projection * vec4(a_position, 1.0);
}
