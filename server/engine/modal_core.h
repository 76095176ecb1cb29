/*
 * modal_core.h — the arithmetic of the modal (Walsh–Hadamard) cube element product, one cell
 * per SIMD lane, for any GCC vector type: fem.c instantiates it in double, mg.c (the V-cycle)
 * in float. The derivation is in fem.c above modal_kernel.
 *
 * A template header, without include guard: define before including
 *   MODAL_NAME  the function's name
 *   MODAL_V     the vector type (GCC vector_size), MODAL_S its element type
 * and get
 *   static void MODAL_NAME(const MODAL_V u[24], const MODAL_V *R, MODAL_S rest,
 *                          const MODAL_V *L, const MODAL_V *M, MODAL_V *e, MODAL_V y[24]);
 * which computes, per lane, y = R K (Rᵀ u − rest·corner) with K the cube stiffness of
 * hλ = 16 L, hμ = 16 M (R NULL: identity; rest 0: no rest shape) and, if e is not NULL, the energy
 * e = ½ (Rᵀu − rest)ᵀ K (Rᵀu − rest). It is always inlined, so that it is compiled for the
 * target (clone) of its caller; every lane does the same operations in the same order, so a
 * cell's result does not depend on its lane. The caller loads u and R and stores y.
 *
 * Flops per lane: transform 69, mode gradients 50, back 69 (MODAL_FLOPS_CORE); the two
 * rotations 2·105 (MODAL_FLOPS_ROT); the energy 41 more.
 */

#ifndef MODAL_FLOPS_CORE
#define MODAL_FLOPS_CORE (69.0 + 50.0 + 69.0)
#define MODAL_FLOPS_ROT 210.0
#endif

static inline __attribute__((always_inline)) void
MODAL_NAME(const MODAL_V u[24], const MODAL_V *R, MODAL_S rest, const MODAL_V *Lp,
           const MODAL_V *Mp, MODAL_V *e, MODAL_V y[24])
{
    typedef MODAL_V V;
    typedef MODAL_S S;
    const V L = *Lp, M = *Mp;
    V a[8][3], g[8][3];
    /* forward transform, per component */
    for (int i = 0; i < 3; i++) {
        const V s00 = u[3 * 1 + i] + u[3 * 0 + i], d00 = u[3 * 1 + i] - u[3 * 0 + i];
        const V s10 = u[3 * 2 + i] + u[3 * 3 + i], d10 = u[3 * 2 + i] - u[3 * 3 + i];
        const V s01 = u[3 * 5 + i] + u[3 * 4 + i], d01 = u[3 * 5 + i] - u[3 * 4 + i];
        const V s11 = u[3 * 6 + i] + u[3 * 7 + i], d11 = u[3 * 6 + i] - u[3 * 7 + i];
        const V ss0 = s10 + s00, sd0 = s10 - s00, ss1 = s11 + s01, sd1 = s11 - s01;
        const V ds0 = d10 + d00, dd0 = d10 - d00, ds1 = d11 + d01, dd1 = d11 - d01;
        a[1][i] = ds1 + ds0;
        a[2][i] = sd1 + sd0;
        a[3][i] = ss1 - ss0;
        a[4][i] = dd1 + dd0;
        a[5][i] = sd1 - sd0;
        a[6][i] = ds1 - ds0;
        a[7][i] = dd1 - dd0;
    }
    if (R)
        for (int m = 1; m < 8; m++) {
            const V v0 = a[m][0], v1 = a[m][1], v2 = a[m][2];
            for (int i = 0; i < 3; i++)
                a[m][i] = R[i] * v0 + R[3 + i] * v1 + R[6 + i] * v2;
        }
    if (rest != 0) {
        const S r4 = (S)4 * rest;
        a[1][0] -= r4;
        a[2][1] -= r4;
        a[3][2] -= r4;
    }
    /* mode gradients */
    const V M2 = M + M;
    const V L1 = L * (S)(1.0 / 3.0), M1 = M * (S)(1.0 / 3.0),
            Q = (L + (S)4 * M) * (S)(1.0 / 9.0);
    {
        const V lt = L * (a[1][0] + a[2][1] + a[3][2]);
        g[1][0] = lt + M2 * a[1][0];
        g[2][1] = lt + M2 * a[2][1];
        g[3][2] = lt + M2 * a[3][2];
        const V o01 = M * (a[2][0] + a[1][1]), o02 = M * (a[3][0] + a[1][2]),
                o12 = M * (a[3][1] + a[2][2]);
        g[2][0] = g[1][1] = o01;
        g[3][0] = g[1][2] = o02;
        g[3][1] = g[2][2] = o12;
    }
    {
        const V tx = L1 * (a[4][1] + a[6][2]), ty = L1 * (a[4][0] + a[5][2]),
                tz = L1 * (a[6][0] + a[5][1]);
        const V w = a[4][2] + a[5][0] + a[6][1];
        g[4][0] = ty + M * a[4][0];
        g[4][1] = tx + M * a[4][1];
        g[4][2] = M1 * (a[4][2] + w);
        g[5][0] = M1 * (a[5][0] + w);
        g[5][1] = tz + M * a[5][1];
        g[5][2] = ty + M * a[5][2];
        g[6][0] = tz + M * a[6][0];
        g[6][1] = M1 * (a[6][1] + w);
        g[6][2] = tx + M * a[6][2];
        for (int i = 0; i < 3; i++)
            g[7][i] = Q * a[7][i];
    }
    if (e) {
        V en = a[1][0] * g[1][0];
        for (int m = 1; m < 8; m++)
            for (int i = (m == 1); i < 3; i++)
                en += a[m][i] * g[m][i];
        *e = en * (S)0.5;
    }
    if (R)
        for (int m = 1; m < 8; m++) {
            const V v0 = g[m][0], v1 = g[m][1], v2 = g[m][2];
            for (int i = 0; i < 3; i++)
                g[m][i] = R[3 * i] * v0 + R[3 * i + 1] * v1 + R[3 * i + 2] * v2;
        }
    /* transposed transform back to the nodes (g_0 = 0) */
    for (int i = 0; i < 3; i++) {
        const V sd1 = g[2][i] + g[5][i], sd0 = g[2][i] - g[5][i];
        const V ds1 = g[1][i] + g[6][i], ds0 = g[1][i] - g[6][i];
        const V dd1 = g[4][i] + g[7][i], dd0 = g[4][i] - g[7][i];
        const V ss1 = g[3][i];
        /* ss0 = -g3: folded into the next stage */
        const V s10 = sd0 - ss1, s00 = -(sd0 + ss1), s11 = ss1 + sd1, s01 = ss1 - sd1;
        const V d10 = ds0 + dd0, d00 = ds0 - dd0, d11 = ds1 + dd1, d01 = ds1 - dd1;
        y[3 * 0 + i] = s00 - d00;
        y[3 * 1 + i] = s00 + d00;
        y[3 * 3 + i] = s10 - d10;
        y[3 * 2 + i] = s10 + d10;
        y[3 * 4 + i] = s01 - d01;
        y[3 * 5 + i] = s01 + d01;
        y[3 * 7 + i] = s11 - d11;
        y[3 * 6 + i] = s11 + d11;
    }
}

#undef MODAL_NAME
#undef MODAL_V
#undef MODAL_S
