/* additive: C = sum a_k * c_k, A = max a_k. With NORM_TIME the colour is divided per channel
 * by N = sum a_t * rgb_t (norm.xyz; a channel with N = 0 gives 0) and clamped to A here;
 * otherwise the raw sums are written and the host normalises by the volume's maximum. */
__kernel void integrate_additive(KERNEL_ARGS, const float4 norm, __global float4 *out)
{
    VOXEL_PROLOGUE
    floatv cr = 0.0f, cg = 0.0f, cb = 0.0f, ca = 0.0f;
    for (int i = 0; i < w; ++i) {
        const int k = order[i];
        const DATA_V raw = RAW(k);
#ifdef SKIP_EMPTY
        if (!IS_LIVE(raw)) continue; /* adds 0 to the sums and cannot raise the maximum */
#endif
        LutPos p;
        LOCATE(raw, p)
        const float4 t = tc[k];
        floatv r, g, b;
        STEP_COLOR(lut, p, t, r, g, b)
        const floatv ak = STEP_ALPHA(lut, p, t, k);
        cr += ak * r;
        cg += ak * g;
        cb += ak * b;
        ca = fmax(ca, ak);
    }
#ifdef NORM_TIME
    cr = norm.x > 0.0f ? fmin(cr / norm.x, ca) : (floatv)(0.0f);
    cg = norm.y > 0.0f ? fmin(cg / norm.y, ca) : (floatv)(0.0f);
    cb = norm.z > 0.0f ? fmin(cb / norm.z, ca) : (floatv)(0.0f);
#endif
    STORE_RGBA(o, cr, cg, cb, ca);
}
