/* first_hit: the first step in the order whose opacity exceeds the threshold supplies the
 * voxel: (a_k * c_k, a_k) and t_index = s_k; none: (0, 0, 0, 0) and -1. */
__kernel void integrate_first_hit(KERNEL_ARGS, const float threshold, __global float4 *out,
                                  __global int *t_index)
{
    VOXEL_PROLOGUE
    floatv hr = 0.0f, hg = 0.0f, hb = 0.0f, ha = 0.0f;
    intv hit = -1;
    for (int i = 0; i < w; ++i) {
        const int k = order[i];
        const DATA_V raw = RAW(k);
#ifdef SKIP_EMPTY
        if (!IS_LIVE(raw)) continue; /* opacity 0 never passes a threshold >= 0 */
#endif
        LutPos p;
        LOCATE(raw, p)
        const float4 t = tc[k];
        floatv r, g, b;
        STEP_COLOR(lut, p, t, r, g, b)
        const floatv ak = STEP_ALPHA(lut, p, t, k);
        const intv take = (hit < 0) & (ak > threshold);
        hr = SELECT(hr, ak * r, take);
        hg = SELECT(hg, ak * g, take);
        hb = SELECT(hb, ak * b, take);
        ha = SELECT(ha, ak, take);
        hit = SELECT(hit, (intv)(steps[k]), take);
        if (ALL(hit >= 0)) break;
    }
    STORE_RGBA(o, hr, hg, hb, ha);
    STORE_INT(hit, t_index + o);
}
