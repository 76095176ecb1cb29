/*
 * mat3.h — the few 3×3 matrix helpers the engine shares (row-major double[9]).
 */
#ifndef CS_MAT3_H
#define CS_MAT3_H

/* Adjugate (transposed cofactors) of m into c; returns det(m). m⁻¹ = c / det. */
static inline double cs_mat3_adjugate(const double m[9], double c[9])
{
    c[0] = m[4] * m[8] - m[5] * m[7];
    c[1] = m[2] * m[7] - m[1] * m[8];
    c[2] = m[1] * m[5] - m[2] * m[4];
    c[3] = m[5] * m[6] - m[3] * m[8];
    c[4] = m[0] * m[8] - m[2] * m[6];
    c[5] = m[2] * m[3] - m[0] * m[5];
    c[6] = m[3] * m[7] - m[4] * m[6];
    c[7] = m[1] * m[6] - m[0] * m[7];
    c[8] = m[0] * m[4] - m[1] * m[3];
    return m[0] * c[0] + m[1] * c[3] + m[2] * c[6];
}

#endif
