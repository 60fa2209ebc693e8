// microfacet GLSL: constants, erfcx and the Fresnel terms (thesis Sec. 2.1, Table 2.I).
// Directions are unit vectors in the local shading frame (z = macro normal), pointing away
// from the surface; wi is the light direction, wo the view direction.

const float MF_PI = 3.14159265358979;
const float MF_SQRT_PI = 1.7724538509055159;
const float MF_HALF_PI = 1.5707963267948966;
const float MF_BIG = 1e30;      // stands for +infinity (Lambda below the mesosurface)

// Scaled complementary error function erfcx(x) = exp(x^2) erfc(x), x >= 0 (Numerical
// Recipes' Chebyshev fit of erfc, fractional error < 1.2e-7 everywhere).
float mf_erfcx(float x) {
    float t = 1.0 / (1.0 + 0.5 * x);
    return t * exp(-1.26551223 + t * (1.00002368 + t * (0.37409196 + t * (0.09678418
        + t * (-0.18628806 + t * (0.27886807 + t * (-1.13520398 + t * (1.48851587
        + t * (-0.82215223 + t * 0.17087277)))))))));
}

// Fresnel term F(cos theta_d) -> RGB. kind: MF_FRESNEL_IDEAL (F = 1, Eq. 2.3),
// MF_FRESNEL_SCHLICK (a = F0, b = F90), MF_FRESNEL_DIELECTRIC (a = eta), MF_FRESNEL_CONDUCTOR
// (a = eta, b = k), MF_FRESNEL_TABLE (the fit's table, tabulated.glsl).
const int MF_FRESNEL_IDEAL = 0;
const int MF_FRESNEL_SCHLICK = 1;
const int MF_FRESNEL_DIELECTRIC = 2;
const int MF_FRESNEL_CONDUCTOR = 3;
const int MF_FRESNEL_TABLE = 4;
struct MfFresnel { int kind; vec3 a; vec3 b; };

// Schlick: F = F0 + (F90 - F0)(1 - c)^5 (Table 2.I for F90 = 1).
vec3 mf_fresnel_schlick(vec3 f0, vec3 f90, float c) {
    float m = 1.0 - clamp(c, 0.0, 1.0);
    float m2 = m * m;
    return f0 + (f90 - f0) * (m2 * m2 * m);
}

// Dielectric of real index eta: F = 1/2 (g-c)^2/(g+c)^2 [1 + (c(g+c)-1)^2/(c(g-c)+1)^2],
// g^2 = eta^2 + c^2 - 1; total internal reflection gives 1 (Table 2.I).
vec3 mf_fresnel_dielectric(vec3 eta, float c) {
    c = clamp(c, 0.0, 1.0);
    vec3 g2 = eta * eta + c * c - 1.0;
    vec3 g = sqrt(max(g2, 0.0));
    vec3 a = (g - c) / (g + c);
    vec3 b = (c * (g + c) - 1.0) / (c * (g - c) + 1.0);
    vec3 f = 0.5 * a * a * (1.0 + b * b);
    return mix(f, vec3(1.0), lessThan(g2, vec3(0.0)));
}

// Conductor of complex index eta + i k, unpolarized (|r_s|^2 + |r_p|^2) / 2 in real
// arithmetic (microfacet.fresnel.Conductor).
vec3 mf_fresnel_conductor(vec3 eta, vec3 k, float c) {
    c = clamp(c, 0.0, 1.0);
    float c2 = c * c;
    float s2 = 1.0 - c2;
    vec3 t1 = eta * eta - k * k - s2;
    vec3 a2b2 = sqrt(t1 * t1 + 4.0 * eta * eta * k * k);
    vec3 ac2 = 2.0 * c * sqrt(max(0.5 * (a2b2 + t1), 0.0));
    vec3 rs = (a2b2 + c2 - ac2) / (a2b2 + c2 + ac2);
    vec3 t3 = a2b2 * c2 + s2 * s2;
    vec3 t4 = ac2 * s2;
    return 0.5 * (rs + rs * (t3 - t4) / (t3 + t4));
}

#ifdef MF_TABULATED
vec3 mf_fresnel_table(float c);
#endif

vec3 mf_fresnel(MfFresnel f, float c) {
    if (f.kind == MF_FRESNEL_SCHLICK) return mf_fresnel_schlick(f.a, f.b, c);
    if (f.kind == MF_FRESNEL_DIELECTRIC) return mf_fresnel_dielectric(f.a, c);
    if (f.kind == MF_FRESNEL_CONDUCTOR) return mf_fresnel_conductor(f.a, f.b, c);
#ifdef MF_TABULATED
    if (f.kind == MF_FRESNEL_TABLE) return mf_fresnel_table(c);
#endif
    return vec3(1.0);
}
