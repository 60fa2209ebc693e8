// microfacet viewer: fragment shader. One of three methods shades the displaced surface
// (LEADR pyramid merged with the base material, thesis Ch. 5, Fig. 5.2):
//   0 naive MIP  - the naive pyramid (averaged normals + base lobe), one filtered lookup
//   1 LEADR      - the merged moment pyramid, one filtered lookup (mf_lookup)
//   2 reference  - N x N samples of level 0 over the pixel footprint, each shaded with its
//                  own directions, weighted by its projected area toward the eye
// under a point light at u_light (irradiance u_intensity / r^2; masking only, as the
// library's LEADR figures) or the environment (N x N grid, Sec. 3.5), plus an optional
// rough-diffuse SH term. Output: linear radiance, or exposed sRGB when u_display.
#include "tabulated.glsl"
#include "leadr.glsl"

in vec3 v_world;
in vec2 v_uv;
in vec3 v_tangent;
in vec3 v_normal;
out vec4 o_color;

uniform int u_method;
uniform int u_light_kind;          // 0 point light, 1 environment
uniform int u_supersampling;       // N of the reference
uniform vec3 u_eye;                // shading eye (world)
uniform vec3 u_light;
uniform float u_intensity;
uniform MfFresnel u_fresnel;
uniform highp sampler2D u_leadr_a;
uniform highp sampler2D u_leadr_b;
uniform int u_leadr_top;
uniform highp sampler2D u_naive_a;
uniform highp sampler2D u_naive_b;
uniform int u_naive_top;
uniform highp sampler2D u_env;
uniform int u_env_top;
uniform float u_env_T;
uniform int u_grid;
uniform vec3 u_sh[9];
uniform vec3 u_albedo;             // rough diffuse reflectance (0: specular only)
uniform bool u_display;
uniform float u_exposure;

vec3 shade(MfMoments e, vec3 p, mat3 frame) {
    vec3 wo = normalize(u_eye - p) * frame;            // world -> local (frame is orthonormal)
    vec3 c = vec3(0.0);
    if (u_light_kind == 0) {
        vec3 to_light = u_light - p;
        vec3 wi = normalize(to_light) * frame;
        c = mf_point_light(e, wi, wo, vec3(u_intensity / dot(to_light, to_light)), u_fresnel, false);
    } else {
        c = mf_env_specular(e, wo, frame, u_env, u_env_top, u_env_T, u_grid, u_fresnel,
                            mf_lod_bias(u_grid), true);
    }
    if (u_albedo != vec3(0.0)) c += mf_diffuse_sh(e, wo, frame, u_sh, u_albedo, u_grid, true);
    return c;
}

vec3 to_srgb(vec3 x) {
    x = clamp(x, 0.0, 1.0);
    return mix(12.92 * x, 1.055 * pow(x, vec3(1.0 / 2.4)) - 0.055, greaterThan(x, vec3(0.0031308)));
}

void main() {
    vec3 n = normalize(v_normal);
    vec3 s = normalize(v_tangent - dot(v_tangent, n) * n);
    mat3 frame = mat3(s, cross(n, s), n);
    vec2 dx = dFdx(v_uv), dy = dFdy(v_uv);
    vec3 c;
    if (u_method == 2) {
        vec3 px = dFdx(v_world), py = dFdy(v_world);
        int N = max(u_supersampling, 1);
        vec3 num = vec3(0.0);
        float den = 0.0;
        for (int i = 0; i < N; ++i) {
            for (int j = 0; j < N; ++j) {
                vec2 o = (vec2(float(i), float(j)) + 0.5) / float(N) - 0.5;
                vec2 uv = v_uv + o.x * dx + o.y * dy;
                vec3 p = v_world + o.x * px + o.y * py;
                MfMoments e = MfMoments(mf_sample_level(u_leadr_a, uv, 0, bvec2(true)),
                                        mf_sample_level(u_leadr_b, uv, 0, bvec2(true)).x);
                float a = mf_leadr_projected_area(e, normalize(u_eye - p) * frame);
                num += a * shade(e, p, frame);
                den += a;
            }
        }
        c = den > 0.0 ? num / den : vec3(0.0);
    } else if (u_method == 0) {
        c = shade(mf_lookup(u_naive_a, u_naive_b, u_naive_top, v_uv, dx, dy, 16), v_world, frame);
    } else {
        c = shade(mf_lookup(u_leadr_a, u_leadr_b, u_leadr_top, v_uv, dx, dy, 16), v_world, frame);
    }
    o_color = u_display ? vec4(to_srgb(c * exp2(u_exposure)), 1.0) : vec4(c, 1.0);
}
