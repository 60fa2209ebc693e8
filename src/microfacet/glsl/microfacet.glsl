// microfacet GLSL: the noncentral microfacet BRDF f = F D G / (4 cos_i cos_o) (thesis Eq. 2.1)
// over a standard slope distribution (Beckmann, GGX or a fitted table) mapped by the
// roughness (alpha_x, alpha_y), correlation rho and mean slope (x~n, y~n) (Eq. 3.4).
// Reference: microfacet.distributions (SlopeDistribution) and microfacet.brdf (NumPy).
#include "common.glsl"

const int MF_BECKMANN = 0;
const int MF_GGX = 1;
const int MF_TABULATED_DISTRIBUTION = 2;

// A surface: standard distribution `dist`, alpha = (alpha_x, alpha_y) > 0, |rho| < 1,
// mean_slope = (x~n, y~n).
struct MfSurface { int dist; vec2 alpha; float rho; vec2 mean_slope; };

#ifdef MF_TABULATED
float mf_tab_p22_std_over_z4(vec2 m, float z);
float mf_tab_lambda_std(vec3 warped);
#endif

// Inverse of the linear part of Eq. 3.4 applied to a slope offset d (standard slope).
vec2 mf_unscale(MfSurface s, vec2 d) {
    float sq = sqrt(1.0 - s.rho * s.rho);
    return vec2(d.x / s.alpha.x,
                (s.alpha.x * d.y - s.rho * s.alpha.y * d.x) / (s.alpha.x * s.alpha.y * sq));
}

// Standard P22(x / z, y / z) / z^4 for z > 0 (Table 2.II): Beckmann exp(-r^2) / pi,
// GGX 1 / (pi (1 + r^2)^2), written division-free in z (finite at grazing normals).
float mf_p22_std_over_z4(int dist, vec2 m, float z) {
    float r2 = dot(m, m);
    if (dist == MF_BECKMANN) return exp(-r2 / (z * z) - 4.0 * log(z)) / MF_PI;
#ifdef MF_TABULATED
    if (dist == MF_TABULATED_DISTRIBUTION) return mf_tab_p22_std_over_z4(m, z);
#endif
    float r = z * z + r2;
    return 1.0 / (MF_PI * r * r);
}

// NDF D(h) = P22(h~) / cos^4 theta_h (Eq. 2.11, 3.2); 0 below the horizon.
float mf_ndf(MfSurface s, vec3 h) {
    float z = h.z;
    if (z <= 0.0) return 0.0;
    vec2 m = mf_unscale(s, -h.xy - s.mean_slope * z);
    float det = s.alpha.x * s.alpha.y * sqrt(1.0 - s.rho * s.rho);
    return mf_p22_std_over_z4(s.dist, m, z) / det;
}

// Unnormalized standard direction k' = (a, b, c) of k (Eq. 3.3); c = c_k is the cosine
// of k with the mesonormal (-x~n, -y~n, 1).
vec3 mf_warp(MfSurface s, vec3 k) {
    float sq = sqrt(1.0 - s.rho * s.rho);
    return vec3(s.alpha.x * k.x + s.rho * s.alpha.y * k.y, s.alpha.y * sq * k.y,
                k.z - dot(k.xy, s.mean_slope));
}

// Beckmann Lambda(v) = (exp(-v^2) / (v sqrt(pi)) - erfc(v)) / 2, v = cot theta (Table 2.III).
float mf_beckmann_lambda(float v) {
    return max(0.5 * exp(-v * v) * (1.0 / (v * MF_SQRT_PI) - mf_erfcx(v)), 0.0);
}

// Smith Lambda(k) = Lambda_std(k') of the warped direction (Eq. 3.3); MF_BIG where c <= 0.
float mf_lambda(MfSurface s, vec3 k) {
    vec3 w = mf_warp(s, k);
    float r2 = dot(w.xy, w.xy);
    if (w.z <= 0.0) return MF_BIG;
    if (r2 <= 0.0) return 0.0;
    if (s.dist == MF_BECKMANN) return mf_beckmann_lambda(w.z / sqrt(r2));
#ifdef MF_TABULATED
    if (s.dist == MF_TABULATED_DISTRIBUTION) return mf_tab_lambda_std(w);
#endif
    return r2 / (2.0 * w.z * (sqrt(r2 + w.z * w.z) + w.z));    // GGX, cancellation-free
}

// Projected area of the microsurface toward k, A(k) = c_k (1 + Lambda(k)) (Eq. 3.3); 0 if c_k <= 0.
float mf_projected_area(MfSurface s, vec3 k) {
    float c = k.z - dot(k.xy, s.mean_slope);
    return c > 0.0 ? c * (1.0 + mf_lambda(s, k)) : 0.0;
}

// Smith masking G1(k) = z_k / A(k) (Eq. 2.14, 3.3).
float mf_g1(MfSurface s, vec3 k) {
    float a = mf_projected_area(s, k);
    return (k.z > 0.0 && a > 0.0) ? k.z / a : 0.0;
}

// D G / (4 cos_o) at the half vector: height-correlated Smith
// G = (z_o / c_o) / (1 + Lambda(i) + Lambda(o)) (LEADR supplemental Sec. 3.3; Eq. 2.13 at
// zero mean slope), or masking only G = G1(o) without shadowing. 0 where invalid.
float mf_projected(MfSurface s, bool shadowing, vec3 wi, vec3 wo) {
    vec3 h = normalize(wi + wo);
    float oh = dot(wo, h);
    float co = wo.z - dot(wo.xy, s.mean_slope);
    if (wi.z <= 0.0 || wo.z <= 0.0 || oh <= 0.0 || h.z <= 0.0 || co <= 0.0) return 0.0;
    float lam = mf_lambda(s, wo) + (shadowing ? mf_lambda(s, wi) : 0.0);
    return mf_ndf(s, h) / (4.0 * co * (1.0 + lam));
}

// f cos theta_i = F(o.h) D G / (4 cos theta_o) (Listing 2.2).
vec3 mf_eval_cos(MfSurface s, MfFresnel f, bool shadowing, vec3 wi, vec3 wo) {
    float p = mf_projected(s, shadowing, wi, wo);
    if (p <= 0.0) return vec3(0.0);
    return mf_fresnel(f, dot(wo, normalize(wi + wo))) * p;
}

// f = F D G / (4 cos theta_i cos theta_o) (Eq. 2.1).
vec3 mf_eval(MfSurface s, MfFresnel f, bool shadowing, vec3 wi, vec3 wo) {
    return wi.z > 0.0 ? mf_eval_cos(s, f, shadowing, wi, wo) / wi.z : vec3(0.0);
}
