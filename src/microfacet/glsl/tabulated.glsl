// microfacet GLSL: the fitted tabulated microfacet BRDF of `microfacet fit` (thesis Ch. 4;
// Dupuy et al. 2015), isotropic fits: f = F D G / (4 cos_i cos_o) + k_d / pi (Eq. 2.1, 1.9)
// with D, Lambda and F read from one small float texture (microfacet.glsl.export_textures):
//
//   mf_fit_table  RGBA32F, width max(N, M, K), 3 rows, NEAREST, texelFetch only:
//     row 0, x: ln D_j of the standard surface at theta_j = (j / (N - 1))^2 pi / 2 (Listing 4.1)
//     row 1, xy: L1_k and dL1/ds_k * h on the fine grid s_k = k / (M - 1), h = 1 / (M - 1),
//                slope xi_k = tan(s_k^2 theta_cap)  (Lambda(a) = L1(a) / a, Eq. 2.14)
//     row 2, rgba: Fresnel F_j (rgb) at cos theta_d = a, increasing (Eq. 4.11)
//   mf_fit_sizes  (N, M, K)
// Reference: microfacet.distributions.tabulated.TabulatedIsotropic, microfacet.fit.FittedBRDF.
#define MF_TABULATED 1
#include "microfacet.glsl"

uniform highp sampler2D mf_fit_table;
uniform ivec3 mf_fit_sizes;

const float MF_THETA_CAP = 1.5707962267948967;    // atan(1e7)

// D interpolated log-linearly in theta between the nodes of Listing 4.1.
float mf_tab_d(float theta) {
    int n = mf_fit_sizes.x;
    theta = clamp(theta, 0.0, MF_HALF_PI);
    float u = sqrt(theta / MF_HALF_PI) * float(n - 1);
    int i = min(int(u), n - 2);
    float fi = float(i);
    float t = clamp((u - fi) * (u + fi) / (2.0 * fi + 1.0), 0.0, 1.0);   // theta = (u / (n-1))^2 pi/2
    float la = texelFetch(mf_fit_table, ivec2(i, 0), 0).x;
    float lb = texelFetch(mf_fit_table, ivec2(i + 1, 0), 0).x;
    return exp(la + t * (lb - la));
}

// P22(x / z, y / z) / z^4 = D(theta) / (z^2 + r^2)^2, tan theta = r / z (Eq. 2.11).
float mf_tab_p22_std_over_z4(vec2 m, float z) {
    float r2 = dot(m, m);
    float q = z * z + r2;
    return mf_tab_d(atan(sqrt(r2), z)) / (q * q);
}

// Lambda(a) = L1(a) / a, a = cot theta (Eq. 2.14 for radial P), L1 cubic Hermite in s.
float mf_tab_lambda_std(float a) {
    int m = mf_fit_sizes.y;
    float s = sqrt(min(atan(a), MF_THETA_CAP) / MF_THETA_CAP);
    float f = s * float(m - 1);
    int k = min(int(f), m - 2);
    float t = clamp(f - float(k), 0.0, 1.0);
    vec2 p0 = texelFetch(mf_fit_table, ivec2(k, 1), 0).xy;
    vec2 p1 = texelFetch(mf_fit_table, ivec2(k + 1, 1), 0).xy;
    float t2 = t * t, t3 = t2 * t;
    float l1 = (2.0 * t3 - 3.0 * t2 + 1.0) * p0.x + (t3 - 2.0 * t2 + t) * p0.y
             + (-2.0 * t3 + 3.0 * t2) * p1.x + (t3 - t2) * p1.y;
    return max(l1, 0.0) / a;
}

// The Fresnel table, piecewise linear in cos theta_d, clamped at its ends.
vec3 mf_fresnel_table(float c) {
    int n = mf_fit_sizes.z;
    int lo = 0, hi = n - 1;
    vec4 first = texelFetch(mf_fit_table, ivec2(0, 2), 0);
    vec4 last = texelFetch(mf_fit_table, ivec2(n - 1, 2), 0);
    if (c <= first.a) return first.rgb;
    if (c >= last.a) return last.rgb;
    for (int it = 0; it < 16 && hi - lo > 1; ++it) {
        int mid = (lo + hi) / 2;
        if (texelFetch(mf_fit_table, ivec2(mid, 2), 0).a <= c) lo = mid; else hi = mid;
    }
    vec4 a = texelFetch(mf_fit_table, ivec2(lo, 2), 0);
    vec4 b = texelFetch(mf_fit_table, ivec2(hi, 2), 0);
    return mix(a.rgb, b.rgb, (c - a.a) / (b.a - a.a));
}

// The fitted BRDF times cos theta_i: the microfacet lobe with the tabulated Fresnel plus
// the Lambertian base k_d cos theta_i / pi (FittedBRDF.eval_cos).
vec3 mf_fit_eval_cos(MfSurface s, bool shadowing, vec3 diffuse, vec3 wi, vec3 wo) {
    MfFresnel f = MfFresnel(MF_FRESNEL_TABLE, vec3(0.0), vec3(0.0));
    vec3 spec = mf_eval_cos(s, f, shadowing, wi, wo);
    return spec + ((wi.z > 0.0 && wo.z > 0.0) ? diffuse * wi.z / MF_PI : vec3(0.0));
}
