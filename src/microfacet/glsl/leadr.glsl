// microfacet GLSL: LEADR runtime stage (Dupuy et al. 2013 and its supplemental; thesis
// Ch. 3 and 5.2, Fig. 5.2). A pixel's surface is five linear slope moments
// E = (E[x~], E[y~], E[x~^2], E[y~^2], E[x~ y~]) fetched from a MIP pyramid, merged with the
// base material's (Listing 5.1) and shaded by:
//   mf_point_light      point/directional light, analytic (supplemental Sec. 3.3)
//   mf_env_specular     filtered environment, N x N sample grid + LOD rule (Algorithm 1, Sec. 3.4-3.5)
//   mf_diffuse_sh       rough diffuse, 9-coefficient SH irradiance (Algorithms 2-3, Sec. 3.6)
// with the artificial micronormal fallback (Sec. 3.7) in the grids.
// Moment textures: RGBA32F (E1, E2, E3, E4) + R32F (E5), level k = MIP level k of the
// pyramid file, wrap REPEAT, filter LINEAR_MIPMAP_NEAREST (levels are blended here).
// Reference: microfacet.leadr (mip.lookup, shading, downsample, moments.convolve).
#include "microfacet.glsl"

struct MfMoments { vec4 e1234; float e5; };

const float MF_MIN_VARIANCE = 0.5e-10;
const float MF_MAX_CORRELATION = 0.99;
const float MF_ARTIFICIAL_WEIGHT = 1e-5;
const float MF_ARTIFICIAL_EPSILON = 1.01;
const float MF_GRID_SPACING = 0.9;

MfMoments mf_moments(vec4 e1234, float e5) { return MfMoments(e1234, e5); }

MfMoments mf_scale(MfMoments e, float w) { return MfMoments(e.e1234 * w, e.e5 * w); }

MfMoments mf_add(MfMoments a, MfMoments b) { return MfMoments(a.e1234 + b.e1234, a.e5 + b.e5); }

// Moments of the sum of two independent slopes (Listing 5.1): means and covariances add,
// E3 = Ea3 + Eb3 + 2 Ea1 Eb1, E4 = ... + 2 Ea2 Eb2, E5 = Ea5 + Eb5 + Ea1 Eb2 + Ea2 Eb1.
MfMoments mf_convolve(MfMoments a, MfMoments b) {
    vec2 ma = a.e1234.xy, mb = b.e1234.xy;
    return MfMoments(a.e1234 + b.e1234 + vec4(0.0, 0.0, 2.0 * ma * mb),
                     a.e5 + b.e5 + ma.x * mb.y + ma.y * mb.x);
}

// ---------------------------------------------------------------- lookups
// Bilinear sample of one MIP level at uv (texel centres at (i + 1/2) / W, v = 0 the first
// row), wrapping where `wrap` says, clamping elsewhere. With MF_MANUAL_BILINEAR it is
// computed from texelFetch in float32 (independent of the hardware's filter precision).
int mf_texel_index(int i, int n, bool wrap) {
    return wrap ? i - n * int(floor(float(i) / float(n))) : clamp(i, 0, n - 1);
}

vec4 mf_sample_level(highp sampler2D t, vec2 uv, int level, bvec2 wrap) {
#ifdef MF_MANUAL_BILINEAR
    ivec2 size = max(textureSize(t, 0) >> level, ivec2(1));   // GL's MIP sizes (uniform query:
                                                              // llvmpipe mis-sizes divergent levels)
    vec2 f = uv * vec2(size) - 0.5;
    vec2 f0 = floor(f);
    vec2 w = f - f0;
    ivec2 i0 = ivec2(f0), i1 = i0 + 1;
    ivec2 a = ivec2(mf_texel_index(i0.x, size.x, wrap.x), mf_texel_index(i0.y, size.y, wrap.y));
    ivec2 b = ivec2(mf_texel_index(i1.x, size.x, wrap.x), mf_texel_index(i1.y, size.y, wrap.y));
    vec4 top = mix(texelFetch(t, ivec2(a.x, a.y), level), texelFetch(t, ivec2(b.x, a.y), level), w.x);
    vec4 bottom = mix(texelFetch(t, ivec2(a.x, b.y), level), texelFetch(t, ivec2(b.x, b.y), level), w.x);
    return mix(top, bottom, w.y);
#else
    return textureLod(t, uv, float(level));
#endif
}

// Linear blend of levels floor(lod) and floor(lod) + 1, lod clamped to [0, top].
MfMoments mf_trilinear(highp sampler2D e1234, highp sampler2D e5, int top, vec2 uv, float lod) {
    lod = clamp(lod, 0.0, float(top));
    int k = min(int(floor(lod)), top);
    float t = lod - float(k);
    bvec2 wrap = bvec2(true);
    MfMoments m = MfMoments(mf_sample_level(e1234, uv, k, wrap), mf_sample_level(e5, uv, k, wrap).x);
    if (k < top && t > 0.0) {
        MfMoments n = MfMoments(mf_sample_level(e1234, uv, k + 1, wrap), mf_sample_level(e5, uv, k + 1, wrap).x);
        m = mf_add(mf_scale(m, 1.0 - t), mf_scale(n, t));
    }
    return m;
}

// Filtered moments over the pixel footprint spanned by the uv derivatives a = duv/dx,
// b = duv/dy (microfacet.leadr.lookup): N = min(ceil(major / minor), max_aniso) trilinear
// probes along the major axis (in level-0 texels) at lod = log2(major / N), averaged.
// Moments are linear, so every blend is a valid LEAN filter.
MfMoments mf_lookup(highp sampler2D e1234, highp sampler2D e5, int top, vec2 uv, vec2 a, vec2 b,
                    int max_aniso) {
    vec2 texels = vec2(textureSize(e1234, 0));
    float la = length(a * texels), lb = length(b * texels);
    float major = max(la, lb), minor = min(la, lb);
    vec2 axis = la >= lb ? a : b;
    int n = major > 1.0 ? int(clamp(ceil(major / max(minor, 1e-12)), 1.0, float(max(max_aniso, 1)))) : 1;
    float lod = log2(max(major / float(n), 1.0));
    MfMoments acc = MfMoments(vec4(0.0), 0.0);
    for (int j = 0; j < n; ++j) {
        vec2 p = uv + ((float(j) + 0.5) / float(n) - 0.5) * axis;
        acc = mf_add(acc, mf_trilinear(e1234, e5, top, p, lod));
    }
    return mf_scale(acc, 1.0 / float(n));
}

// ---------------------------------------------------------------- statistics
// Mean (x0, y0) and covariance (var_x, var_y, c_xy) of the slopes (Sec. 3.1), variances
// clamped to MF_MIN_VARIANCE and the correlation to [-0.99, 0.99] (Listing 3.5).
void mf_slope_statistics(MfMoments e, out vec2 mean, out vec3 cov) {
    mean = e.e1234.xy;
    vec2 v = max(e.e1234.zw - mean * mean, vec2(MF_MIN_VARIANCE));
    float lim = MF_MAX_CORRELATION * sqrt(v.x * v.y);
    cov = vec3(v, clamp(e.e5 - mean.x * mean.y, -lim, lim));
}

// The Beckmann surface of the moments: alpha^2 = 2 var, rho = c_xy / sqrt(var_x var_y)
// (Beckmann.from_moments, Eq. 3.5-3.9; var = alpha^2 / 2).
MfSurface mf_surface(MfMoments e) {
    vec2 mean;
    vec3 cov;
    mf_slope_statistics(e, mean, cov);
    return MfSurface(MF_BECKMANN, sqrt(2.0 * cov.xy), cov.z / sqrt(cov.x * cov.y), mean);
}

// Mesonormal (-E1, -E2, 1) / |.| (supplemental Eq. 5).
vec3 mf_mesonormal(MfMoments e) { return normalize(vec3(-e.e1234.xy, 1.0)); }

// Projected area toward k, A(k) = c_k (1 + Lambda(k)) (supplemental Eq. 4, 9).
float mf_leadr_projected_area(MfMoments e, vec3 k) { return mf_projected_area(mf_surface(e), k); }

// ---------------------------------------------------------------- point light
// I = E F(o.h) D(h) / (4 c_o (1 + Lambda(o) [+ Lambda(i)])), c_o = (-x0, -y0, 1).o
// (supplemental Sec. 3.3; shadowing = false drops Lambda(i): masking only).
vec3 mf_point_light(MfMoments e, vec3 wi, vec3 wo, vec3 irradiance, MfFresnel f, bool shadowing) {
    return irradiance * mf_eval_cos(mf_surface(e), f, shadowing, wi, wo);
}

// ---------------------------------------------------------------- sample grids
// Spacing of the n x n grid in standard deviations: 0.9 (n = 5), 6 / (n - 1) from n = 8 (Sec. 3.4).
float mf_grid_spacing(int n) { return n > 1 ? min(MF_GRID_SPACING, 6.0 / float(n - 1)) : 0.0; }

// 1D position p_j and (unnormalized) weight exp(-p^2 / 2) of grid sample j.
float mf_grid_position(int n, int j) { return (float(j) - 0.5 * float(n - 1)) * mf_grid_spacing(n); }

// LOD bias of the n x n grid: 0.5 (n <= 5), -0.5 (32), -1.48 (>= 128), linear in log2 n between.
float mf_lod_bias(int n) {
    float l = log2(float(max(n, 1)));
    float l5 = log2(5.0);
    if (l <= l5) return 0.5;
    if (l <= 5.0) return mix(0.5, -0.5, (l - l5) / (5.0 - l5));
    if (l <= 7.0) return mix(-0.5, -1.48, (l - 5.0) / 2.0);
    return -1.48;
}

// Artificial micronormal (w_n - eps (w_n.o) o) / |.| (Sec. 3.7).
vec3 mf_artificial_micronormal(MfMoments e, vec3 wo) {
    vec3 m = mf_mesonormal(e);
    return normalize(m - MF_ARTIFICIAL_EPSILON * dot(m, wo) * wo);
}

// Grid micronormal k of n x n (k = n * n: the artificial micronormal) and its weight W_k:
// x~ = x0 + p_j sigma_x, y~ = y0 + (r p_j + sqrt(1 - r^2) p_l) sigma_y (Algorithm 1).
vec3 mf_grid_normal(MfMoments e, vec3 wo, int n, int k, out float weight) {
    if (k == n * n) {
        weight = MF_ARTIFICIAL_WEIGHT;
        return mf_artificial_micronormal(e, wo);
    }
    vec2 mean;
    vec3 cov;
    mf_slope_statistics(e, mean, cov);
    float norm = 0.0;
    for (int q = 0; q < n; ++q) {
        float p = mf_grid_position(n, q);
        norm += exp(-0.5 * p * p);
    }
    int j = k / n, l = k - (k / n) * n;
    float pj = mf_grid_position(n, j), pl = mf_grid_position(n, l);
    weight = exp(-0.5 * (pj * pj + pl * pl)) / (norm * norm);
    vec2 sigma = sqrt(cov.xy);
    float r = cov.z / (sigma.x * sigma.y);
    vec2 slope = mean + vec2(pj * sigma.x, (r * pj + sqrt(1.0 - r * r) * pl) * sigma.y);
    return normalize(vec3(-slope, 1.0));
}

// ---------------------------------------------------------------- environment
// Radiance of a lat-long map (row 0 at the zenith, y up, phi = atan2(x, z), image centre
// toward +z: microfacet.render.Environment) at `lod` in [0, top], blending levels floor(lod)
// and floor(lod) + 1 (MipEnvironment.radiance_lod). Wrap in phi, clamp in theta.
vec3 mf_env_radiance(highp sampler2D env, int top, vec3 w, float lod) {
    vec2 uv = vec2(atan(w.x, w.z) / (2.0 * MF_PI) + 0.5, atan(length(w.xz), w.y) / MF_PI);  // not acos: exact at the poles
    lod = clamp(lod, 0.0, float(top));
    int k = min(int(floor(lod)), max(top - 1, 0));
    bvec2 wrap = bvec2(true, false);
    vec3 lo = mf_sample_level(env, uv, k, wrap).rgb;
    if (top > 0) lo += (lod - float(k)) * (mf_sample_level(env, uv, k + 1, wrap).rgb - lo);
    return lo;
}

// I = sum_k W_k F(<n_k,o>) (<n_k,o>+ / n_k,z) L(r_k, LOD_k) / sum_k W_k <n_k,o>+ / n_k,z with
// r_k = reflect(o, n_k) in the world (frame = columns s, t, n), LOD_k = 0.72 ln(4 n_z^3 <n,o>)
// + log2(d max(sigma) T) + bias (Simplified Algorithm 1, Sec. 3.5). T = env height / 2.
// lod_bias: the constant (mf_lod_bias(n) is the library's default).
vec3 mf_env_specular(MfMoments e, vec3 wo, mat3 frame, highp sampler2D env, int top, float T,
                     int n, MfFresnel f, float lod_bias, bool fallback) {
    vec2 mean;
    vec3 cov;
    mf_slope_statistics(e, mean, cov);
    float spacing = n > 1 ? mf_grid_spacing(n) : 1.0;
    float base = lod_bias + log2(spacing * sqrt(max(cov.x, cov.y)) * T);
    vec3 num = vec3(0.0);
    float den = 0.0;
    int count = n * n + (fallback ? 1 : 0);
    for (int k = 0; k < count; ++k) {
        float w;
        vec3 m = mf_grid_normal(e, wo, n, k, w);
        float vn = max(dot(m, wo), 0.0);
        if (vn <= 0.0) continue;
        float zn = max(m.z, 1e-12);
        float a = w * vn / zn;
        vec3 r = frame * (2.0 * dot(wo, m) * m - wo);
        float lod = 0.72 * log(4.0 * zn * zn * zn * vn) + base;
        num += a * mf_fresnel(f, vn) * mf_env_radiance(env, top, r, lod);
        den += a;
    }
    return den > 0.0 ? num / den : vec3(0.0);
}

// ---------------------------------------------------------------- SH diffuse
// Irradiance E(n) of the 9-coefficient SH radiance (order L00, L1-1, L10, L11, L2-2, L2-1,
// L20, L21, L22) at world normal n (Ramamoorthi and Hanrahan 2001, Eq. 13).
vec3 mf_sh_irradiance(vec3 L[9], vec3 n) {
    const float Y4 = 0.54627421529603959, Y1 = 0.48860251190291992, Y3 = 0.31539156525252005;
    const float Y0 = 0.28209479177387814;
    float c1 = MF_PI / 4.0 * Y4, c2 = MF_PI / 3.0 * Y1, c3 = 3.0 * MF_PI / 4.0 * Y3;
    float c4 = MF_PI * Y0, c5 = MF_PI / 4.0 * Y3;
    return c1 * L[8] * (n.x * n.x - n.y * n.y) + c3 * L[6] * n.z * n.z + c4 * L[0] - c5 * L[6]
         + 2.0 * c1 * (L[4] * n.x * n.y + L[7] * n.x * n.z + L[5] * n.y * n.z)
         + 2.0 * c2 * (L[3] * n.x + L[1] * n.y + L[2] * n.z);
}

// I = albedo / pi sum_k W_k (<n_k,o>+ / n_k,z) E(n_k) / sum_k W_k <n_k,o>+ / n_k,z
// (Simplified Algorithm 3, Sec. 3.6); masking only.
vec3 mf_diffuse_sh(MfMoments e, vec3 wo, mat3 frame, vec3 L[9], vec3 albedo, int n, bool fallback) {
    vec3 num = vec3(0.0);
    float den = 0.0;
    int count = n * n + (fallback ? 1 : 0);
    for (int k = 0; k < count; ++k) {
        float w;
        vec3 m = mf_grid_normal(e, wo, n, k, w);
        float vn = max(dot(m, wo), 0.0);
        if (vn <= 0.0) continue;
        float a = w * vn / max(m.z, 1e-12);
        num += a * mf_sh_irradiance(L, frame * m);
        den += a;
    }
    return den > 0.0 ? albedo / MF_PI * num / den : vec3(0.0);
}
