// microfacet GLSL: the fitted tabulated microfacet BRDF of `microfacet fit` (thesis Ch. 4;
// Dupuy et al. 2015), isotropic and anisotropic fits: f = F D G / (4 cos_i cos_o) + k_d / pi
// (Eq. 2.1, 1.9) with D, Lambda and F read from one small float texture
// (microfacet.glsl.export_textures); mf_fit_azimuths = (0, 0) selects the isotropic layout:
//
//   isotropic: mf_fit_table RGBA32F, width max(N, M, K), 3 rows, NEAREST, texelFetch only:
//     row 0, x: ln D_j of the standard surface at theta_j = (j / (N - 1))^2 pi / 2 (Listing 4.1)
//     row 1, xy: L1_k and dL1/ds_k * h on the fine grid s_k = k / (M - 1), h = 1 / (M - 1),
//                slope xi_k = tan(s_k^2 theta_cap)  (Lambda(a) = L1(a) / a, Eq. 2.14)
//     row 2, rgba: Fresnel F_j (rgb) at cos theta_d = a, increasing (Eq. 4.11)
//   mf_fit_sizes (N, M, K)
//
//   anisotropic: mf_fit_table RGBA32F, width max(Nf, Na, K), N + L + 1 rows:
//     rows i < N, x: ln D of the standard surface, refined (Catmull-Rom), at
//                    theta_i = (i / (N - 1))^2 pi / 2 and phi_j = 2 pi j / Nf
//     rows N + l, xy: projected area A(k) (Eq. 2.14) at theta_l, phi_j = 2 pi j / Na, and theta_l
//     row N + L, rgba: the Fresnel table as above
//   mf_fit_sizes (N, L, K), mf_fit_azimuths (Nf, Na)
// Reference: microfacet.distributions.tabulated.TabulatedIsotropic / TabulatedAnisotropic,
// microfacet.fit.FittedBRDF.
#define MF_TABULATED 1
#include "microfacet.glsl"

uniform highp sampler2D mf_fit_table;
uniform ivec3 mf_fit_sizes;
uniform ivec2 mf_fit_azimuths;

const float MF_THETA_CAP = 1.5707962267948967;    // atan(1e7)
const float MF_TWO_PI = 6.28318530717959;

bool mf_tab_anisotropic() { return mf_fit_azimuths.x > 0; }

// Interval i and weight t of theta in the grid theta_i = (i / (n - 1))^2 pi / 2 (Listing 4.1).
void mf_tab_locate(float theta, int n, out int i, out float t) {
    theta = clamp(theta, 0.0, MF_HALF_PI);
    float u = sqrt(theta / MF_HALF_PI) * float(n - 1);
    i = min(int(u), n - 2);
    float fi = float(i);
    t = clamp((u - fi) * (u + fi) / (2.0 * fi + 1.0), 0.0, 1.0);   // theta = (u / (n-1))^2 pi/2
}

// Isotropic D interpolated log-linearly in theta between the nodes of Listing 4.1.
float mf_tab_d(float theta) {
    int i; float t;
    mf_tab_locate(theta, mf_fit_sizes.x, i, t);
    float la = texelFetch(mf_fit_table, ivec2(i, 0), 0).x;
    float lb = texelFetch(mf_fit_table, ivec2(i + 1, 0), 0).x;
    return exp(la + t * (lb - la));
}

// Anisotropic D log-bilinear on the refined (theta, phi) grid (TabulatedAnisotropic._d_interp).
float mf_tab_d_aniso(float theta, float phi) {
    int i; float t;
    mf_tab_locate(theta, mf_fit_sizes.x, i, t);
    int nf = mf_fit_azimuths.x;
    float f = (phi < 0.0 ? phi + MF_TWO_PI : phi) * (float(nf) / MF_TWO_PI);
    int j = min(int(f), nf - 1);
    float w = clamp(f - float(j), 0.0, 1.0);
    int j1 = (j + 1) % nf;
    float a0 = texelFetch(mf_fit_table, ivec2(j, i), 0).x, a1 = texelFetch(mf_fit_table, ivec2(j, i + 1), 0).x;
    float b0 = texelFetch(mf_fit_table, ivec2(j1, i), 0).x, b1 = texelFetch(mf_fit_table, ivec2(j1, i + 1), 0).x;
    float a = a0 + t * (a1 - a0);
    return exp(a + w * (b0 + t * (b1 - b0) - a));
}

// P22(x / z, y / z) / z^4 = D(theta, phi) / (z^2 + r^2)^2, tan theta = r / z, normal
// azimuth phi = atan2(-y, -x) (Eq. 2.11).
float mf_tab_p22_std_over_z4(vec2 m, float z) {
    float r2 = dot(m, m);
    float q = z * z + r2;
    float theta = atan(sqrt(r2), z);
    float d = mf_tab_anisotropic() ? mf_tab_d_aniso(theta, r2 > 0.0 ? atan(-m.y, -m.x) : 0.0)
                                   : mf_tab_d(theta);
    return d / (q * q);
}

// Isotropic Lambda(a) = L1(a) / a, a = cot theta (Eq. 2.14 for radial P), L1 cubic Hermite in s.
float mf_tab_lambda_iso(float a) {
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

// Anisotropic Lambda = A(k') |k'| / c - 1 (Eq. 2.14), A bilinear in (theta, phi) on the nodes
// theta_l = pi/2 sin^2(pi s_l / 2), phi_j = 2 pi j / Na (TabulatedAnisotropic.lambda_warped).
float mf_tab_lambda_aniso(vec3 w) {
    int n = mf_fit_sizes.y, na = mf_fit_azimuths.y, row = mf_fit_sizes.x;
    float theta = atan(length(w.xy), w.z);
    float x = clamp(theta, 0.0, MF_HALF_PI) / MF_HALF_PI;
    float s = atan(sqrt(x), sqrt(1.0 - x)) / MF_HALF_PI * float(n - 1);   // asin(sqrt x): GL asin is coarse
    int i = min(int(s), n - 2);
    float th0 = texelFetch(mf_fit_table, ivec2(0, row + i), 0).y;
    float th1 = texelFetch(mf_fit_table, ivec2(0, row + i + 1), 0).y;
    float t = clamp((theta - th0) / (th1 - th0), 0.0, 1.0);
    float phi = atan(w.y, w.x);
    float f = (phi < 0.0 ? phi + MF_TWO_PI : phi) * (float(na) / MF_TWO_PI);
    int j = min(int(f), na - 1);
    float u = clamp(f - float(j), 0.0, 1.0);
    int j1 = (j + 1) % na;
    float a0 = mix(texelFetch(mf_fit_table, ivec2(j, row + i), 0).x, texelFetch(mf_fit_table, ivec2(j1, row + i), 0).x, u);
    float a1 = mix(texelFetch(mf_fit_table, ivec2(j, row + i + 1), 0).x, texelFetch(mf_fit_table, ivec2(j1, row + i + 1), 0).x, u);
    return max(mix(a0, a1, t) * length(w) / w.z - 1.0, 0.0);
}

// Standard Lambda of the warped direction w = (a, b, c), c > 0, a^2 + b^2 > 0 (Eq. 3.3).
float mf_tab_lambda_std(vec3 w) {
    return mf_tab_anisotropic() ? mf_tab_lambda_aniso(w) : mf_tab_lambda_iso(w.z / sqrt(dot(w.xy, w.xy)));
}

// The Fresnel table, piecewise linear in cos theta_d, clamped at its ends.
vec3 mf_fresnel_table(float c) {
    int n = mf_fit_sizes.z;
    int row = mf_tab_anisotropic() ? mf_fit_sizes.x + mf_fit_sizes.y : 2;
    int lo = 0, hi = n - 1;
    vec4 first = texelFetch(mf_fit_table, ivec2(0, row), 0);
    vec4 last = texelFetch(mf_fit_table, ivec2(n - 1, row), 0);
    if (c <= first.a) return first.rgb;
    if (c >= last.a) return last.rgb;
    for (int it = 0; it < 16 && hi - lo > 1; ++it) {
        int mid = (lo + hi) / 2;
        if (texelFetch(mf_fit_table, ivec2(mid, row), 0).a <= c) lo = mid; else hi = mid;
    }
    vec4 a = texelFetch(mf_fit_table, ivec2(lo, row), 0);
    vec4 b = texelFetch(mf_fit_table, ivec2(hi, row), 0);
    return mix(a.rgb, b.rgb, (c - a.a) / (b.a - a.a));
}

// The fitted BRDF times cos theta_i: the microfacet lobe with the tabulated Fresnel plus
// the Lambertian base k_d cos theta_i / pi (FittedBRDF.eval_cos).
vec3 mf_fit_eval_cos(MfSurface s, bool shadowing, vec3 diffuse, vec3 wi, vec3 wo) {
    MfFresnel f = MfFresnel(MF_FRESNEL_TABLE, vec3(0.0), vec3(0.0));
    vec3 spec = mf_eval_cos(s, f, shadowing, wi, wo);
    return spec + ((wi.z > 0.0 && wo.z > 0.0) ? diffuse * wi.z / MF_PI : vec3(0.0));
}
