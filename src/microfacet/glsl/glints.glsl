// microfacet GLSL: the glint P-BRDF of a normal map's lobe mixture (Chermain, Claux and
// Merillou 2019, "Glint Rendering based on a Multiple-Scattering Patch BRDF", Eq. 7, 9, 13-17
// and Sec. 4.2.2), the GLSL twin of microfacet.glints.pbrdf.eval_cos_footprints.
//
// A pixel's footprint k_P is a Gaussian over uv (centre, covariance (cuu, cvv, cuv) in uv^2).
// Its lobes are the seeds within `cutoff` standard deviations of Sigma_P + sigma_k^2 I per
// axis (sigma_k = spacing / FWHM), weighted by W_i = exp(-q_i / 2) normalized to sum 1 (Eq. 9);
//   D_P(h) = sum W_i P_i(h~) / z_h^4                        (Eq. 9, P_i the lobe's slope Gaussian)
//   A_P(k) = sum W_i max(c_i(k), 0),  c_i = z - x E_i[x~] - y E_i[y~]               (Eq. 17)
//   V_P(k) = sum W_i E[s+], s ~ N(c_i, Var(x x~ + y y~))   (= A_P (1 + Lambda_P), Eq. 13-15)
//   eval_cos(wi, wo) = F D_P G2 / (4 A_P(o)),  G2 / A_P(o) = A_i / (V_o A_i + A_o (V_i - A_i))
// (height-correlated G2; `separable`: A_i / (V_o V_i)). With exact = false, Sec. 4.2.2: A_P(k) =
// V_P c_m+ / V_m of the merged lobe m, the W-average of the lobes of MIP level
// mf_glint_mip_level(cov) (microfacet.glints.microsurface.LobeMixture.mip_moments).
//
// Lobe textures (microfacet.export.glints_threejs.lobe_textures), read with texelFetch (no
// filtering), wrapped by index; MIP level k = the lobe grid's MIP level k (raw moments
// averaged, Sec. 4.2.2), down to 1 x 1:
//   ta  RGBA32F (E[x~], E[y~], Var x~, Var y~)   central slope moments of lobe (row iy, column ix)
//   tb  R32F    Cov(x~, y~)
// Texel (ix, iy) of level k is the seed at uv ((ix + 1/2) / nx, (iy + 1/2) / ny), v = 0 the
// first row. Level 0 is the library's exact sum; a footprint whose window exceeds
// MF_GLINT_MAX_WINDOW lobes per axis is summed over the first MIP level where it fits (the
// multiscale fallback: each coarser lobe carries the moments of the finer ones, LEADR, so the
// P-NDF there is smoothed at that level's scale; the library sums level 0 at every size).
// Directions: local frame (z the macro normal), unit, pointing away from the surface.
#include "common.glsl"

#ifndef MF_GLINT_MAX_WINDOW
#define MF_GLINT_MAX_WINDOW 48
#endif

const float MF_GLINT_FWHM = 2.3548200450309493;       // FWHM / sigma of a Gaussian
const float MF_GLINT_INV_2PI = 0.15915494309189535;
const float MF_GLINT_INV_SQRT_2PI = 0.3989422804014327;
const float MF_GLINT_AREA_T = 8.0;     // c / sigma beyond which E[s+] = c to float32 rounding

// The footprint's lobe window at one level: grid size, inclusive index range (unwrapped),
// centre and the inverse of Sigma_P + sigma_k^2 I as (xx, yy, xy).
struct MfGlintWindow { ivec2 n; ivec2 i0; ivec2 i1; vec2 center; vec3 inv; };

MfGlintWindow mf_glint_window(highp sampler2D ta, int level, vec2 center, vec3 cov, float cutoff) {
    ivec2 n = textureSize(ta, level);
    vec2 nf = vec2(n);
    vec2 ks = 1.0 / (nf * MF_GLINT_FWHM);
    float sxx = cov.x + ks.x * ks.x, syy = cov.y + ks.y * ks.y, sxy = cov.z;
    float det = sxx * syy - sxy * sxy;
    vec2 r = cutoff * sqrt(vec2(sxx, syy));
    ivec2 i0 = ivec2(ceil((center - r) * nf - 0.5));
    ivec2 i1 = ivec2(floor((center + r) * nf - 0.5));
    return MfGlintWindow(n, i0, i1, center, vec3(syy, sxx, -sxy) / det);
}

// The first MIP level (from 0) whose window has at most MF_GLINT_MAX_WINDOW lobes per axis
// (the 1 x 1 level at most).
int mf_glint_level(highp sampler2D ta, vec2 center, vec3 cov, float cutoff) {
    for (int level = 0; level < 24; ++level) {
        MfGlintWindow w = mf_glint_window(ta, level, center, cov, cutoff);
        ivec2 len = w.i1 - w.i0 + 1;
        if ((len.x <= MF_GLINT_MAX_WINDOW && len.y <= MF_GLINT_MAX_WINDOW) || (w.n.x == 1 && w.n.y == 1))
            return level;
    }
    return 0;
}

// MIP level of the merged lobe of Sec. 4.2.2 (LobeMixture.mip_level): floor(log2(sd / spacing))
// for sd, the footprint's largest standard deviation, above the level-0 seed spacing.
int mf_glint_mip_level(highp sampler2D ta, vec3 cov) {
    ivec2 n = textureSize(ta, 0);
    float half_tr = 0.5 * (cov.x + cov.y);
    float sd = sqrt(max(half_tr + sqrt(0.25 * (cov.x - cov.y) * (cov.x - cov.y) + cov.z * cov.z), 0.0));
    float spacing = 1.0 / float(max(n.x, n.y));
    int level = sd > spacing ? int(floor(log2(sd / spacing))) : 0;
    for (int k = 0; k < 24; ++k) {            // clamp to the last level (1 x 1)
        ivec2 m = textureSize(ta, k);
        if (k == level || (m.x == 1 && m.y == 1)) return k;
    }
    return 0;
}

// Footprint weight exp(-q / 2) of the seed (ix, iy) of a window (unwrapped indices).
float mf_glint_weight(MfGlintWindow w, int ix, int iy) {
    vec2 d = (vec2(float(ix), float(iy)) + 0.5) / vec2(w.n) - w.center;
    return exp(-0.5 * (w.inv.x * d.x * d.x + w.inv.y * d.y * d.y + 2.0 * w.inv.z * d.x * d.y));
}

// Lobe `a` = (E[x~], E[y~], Var x~, Var y~), `sxy` = Cov(x~, y~): slope density P_i(s) (Eq. 4).
float mf_glint_p22(vec2 s, vec4 a, float sxy) {
    vec2 d = s - a.xy;
    float det = a.z * a.w - sxy * sxy;
    float q = (a.w * d.x * d.x + a.z * d.y * d.y - 2.0 * sxy * d.x * d.y) / det;
    return exp(-0.5 * q) * MF_GLINT_INV_2PI * inversesqrt(det);
}

// E[s+] for s ~ N(c, var) = c Phi(t) + sigma phi(t), t = c / sigma (the lobe's visible
// projected area toward k, microfacet.glints.pbrdf.lobe_projected_area), with erfcx so that
// neither tail overflows or cancels to a negative value.
float mf_glint_area(float c, float var) {
    float sigma = sqrt(max(var, 0.0));
    if (sigma <= 0.0) return max(c, 0.0);
    float t = c / sigma;
    if (t >= MF_GLINT_AREA_T) return c;
    float e = exp(-0.5 * t * t);
    float r = 0.5 * c * mf_erfcx(abs(t) * 0.7071067811865476);
    float s = sigma * MF_GLINT_INV_SQRT_2PI;
    return t >= 0.0 ? c - e * (r - s) : max(e * (r + s), 0.0);
}

// (c_i(k), Var(x x~ + y y~)) of a lobe toward k.
vec2 mf_glint_toward(vec3 k, vec4 a, float sxy) {
    return vec2(k.z - k.x * a.x - k.y * a.y, k.x * k.x * a.z + 2.0 * k.x * k.y * sxy + k.y * k.y * a.w);
}

// Sums of a footprint (Eq. 9, 13, 17), weights normalized:
// (D_P(h) [with 1 / z_h^4], A_P(i), V_P(i), A_P(o), V_P(o)) as (x, y, z, w) and the last in `vo`.
vec4 mf_glint_sums(highp sampler2D ta, highp sampler2D tb, int level, vec2 center, vec3 cov,
                   float cutoff, vec3 h, vec3 wi, vec3 wo, out float vo) {
    MfGlintWindow w = mf_glint_window(ta, level, center, cov, cutoff);
    ivec2 i1 = min(w.i1, w.i0 + MF_GLINT_MAX_WINDOW - 1);
    bool up = h.z > 0.0;
    vec2 s = up ? -h.xy / h.z : vec2(0.0);
    float wsum = 0.0, d = 0.0, ai = 0.0, vi = 0.0, ao = 0.0;
    vo = 0.0;
    for (int jy = 0; jy < MF_GLINT_MAX_WINDOW; ++jy) {
        int iy = w.i0.y + jy;
        if (iy > i1.y) break;
        int ty = iy - w.n.y * int(floor(float(iy) / float(w.n.y)));
        for (int jx = 0; jx < MF_GLINT_MAX_WINDOW; ++jx) {
            int ix = w.i0.x + jx;
            if (ix > i1.x) break;
            int tx = ix - w.n.x * int(floor(float(ix) / float(w.n.x)));
            float wt = mf_glint_weight(w, ix, iy);
            vec4 a = texelFetch(ta, ivec2(tx, ty), level);
            float sxy = texelFetch(tb, ivec2(tx, ty), level).x;
            vec2 ki = mf_glint_toward(wi, a, sxy), ko = mf_glint_toward(wo, a, sxy);
            wsum += wt;
            if (up) d += wt * mf_glint_p22(s, a, sxy);
            ai += wt * max(ki.x, 0.0);
            vi += wt * mf_glint_area(ki.x, ki.y);
            ao += wt * max(ko.x, 0.0);
            vo += wt * mf_glint_area(ko.x, ko.y);
        }
    }
    if (wsum <= 0.0) { vo = 0.0; return vec4(0.0); }
    float hz2 = h.z * h.z;
    vo /= wsum;
    return vec4(up ? d / (wsum * hz2 * hz2) : 0.0, ai / wsum, vi / wsum, ao / wsum);
}

// The merged lobe of Sec. 4.2.2: the W-average of the raw moments of MIP level `level`
// (LobeMixture.mip_moments), as central moments (E[x~], E[y~], Var x~, Var y~) and `sxy`.
vec4 mf_glint_merged(highp sampler2D ta, highp sampler2D tb, int level, vec2 center, vec3 cov,
                     float cutoff, out float sxy) {
    MfGlintWindow w = mf_glint_window(ta, level, center, cov, cutoff);
    ivec2 i1 = min(w.i1, w.i0 + MF_GLINT_MAX_WINDOW - 1);
    float wsum = 0.0;
    vec4 m = vec4(0.0);       // E[x~], E[y~], E[x~^2], E[y~^2]
    float mxy = 0.0;          // E[x~ y~]
    for (int jy = 0; jy < MF_GLINT_MAX_WINDOW; ++jy) {
        int iy = w.i0.y + jy;
        if (iy > i1.y) break;
        int ty = iy - w.n.y * int(floor(float(iy) / float(w.n.y)));
        for (int jx = 0; jx < MF_GLINT_MAX_WINDOW; ++jx) {
            int ix = w.i0.x + jx;
            if (ix > i1.x) break;
            int tx = ix - w.n.x * int(floor(float(ix) / float(w.n.x)));
            float wt = mf_glint_weight(w, ix, iy);
            vec4 a = texelFetch(ta, ivec2(tx, ty), level);
            float c = texelFetch(tb, ivec2(tx, ty), level).x;
            wsum += wt;
            m += wt * vec4(a.xy, a.zw + a.xy * a.xy);
            mxy += wt * (c + a.x * a.y);
        }
    }
    m /= wsum;
    sxy = mxy / wsum - m.x * m.y;
    return vec4(m.xy, max(m.zw - m.xy * m.xy, vec2(0.0)));
}

// A_P = V_P c_m+ / V_m of the approximation (pbrdf._merged_area); `v` is V_P.
float mf_glint_merged_area(float v, vec4 m, float sxy, vec3 k) {
    vec2 t = mf_glint_toward(k, m, sxy);
    float vm = mf_glint_area(t.x, t.y);
    return (vm > 0.0 && t.x > 0.0) ? v * t.x / vm : 0.0;
}

// D_P G2 / (4 A_P(o)) of the footprint (eval_cos without the Fresnel factor F(o.h); the
// caller multiplies by F and by the light's irradiance I / r^2 at normal incidence):
// microfacet.glints.pbrdf.eval_cos_footprints, float32. 0 below either horizon or where
// o.h <= 0 or i.h <= 0 (Eq. 10).
float mf_glint_eval_cos(highp sampler2D ta, highp sampler2D tb, vec2 center, vec3 cov, float cutoff,
                        vec3 wi, vec3 wo, bool exact, bool separable) {
    vec3 h = normalize(wi + wo);
    if (wi.z <= 0.0 || wo.z <= 0.0 || dot(wo, h) <= 0.0 || dot(wi, h) <= 0.0 || h.z <= 0.0) return 0.0;
    int level = mf_glint_level(ta, center, cov, cutoff);
    float vo;
    vec4 s = mf_glint_sums(ta, tb, level, center, cov, cutoff, h, wi, wo, vo);
    float ai = s.y, vi = s.z, ao = s.w;
    if (!exact) {
        float mxy;
        vec4 m = mf_glint_merged(ta, tb, max(mf_glint_mip_level(ta, cov), level), center, cov, cutoff, mxy);
        ai = mf_glint_merged_area(vi, m, mxy, wi);
        ao = mf_glint_merged_area(vo, m, mxy, wo);
    }
    float den = separable ? vo * vi : vo * ai + ao * (vi - ai);
    return (den > 0.0 && ai > 0.0) ? 0.25 * s.x * ai / den : 0.0;
}
