/* Normals of EPPF_NRM_LANES (eight) neighborhoods at once, one per vector
 * lane, for one SIMD level: a template that _normals_simd.h includes once
 * per level with these defined (undefined again at the end):
 *
 *   EPPF_NRM_L_NAME(f)   the level's name for function f (f##_avx2, ...);
 *   EPPF_NRM_L_ATTR      its target attribute (empty for the portable level);
 *   EPPF_NRM_L_VT/_VL    GCC/clang vectors of EPPF_NRM_L_W doubles / 64-bit
 *                        integers, W the target's register width: the eight
 *                        lanes go W at a time, so that the running values
 *                        stay in registers.
 *
 * eppf_nrm_cov8_*: the covariance of each lane's neighborhood, from the
 * points staged in ``nb``: x of neighbor i of lane l at nb[8 i + l], y at
 * nb[8 (k + i) + l], z at nb[8 (2 k + i) + l], each lane's neighbors in the
 * order of its ``kpos``. The sums are eppf_nrm_covariance's, each in the
 * same order (two sums per register there, one lane per neighborhood here:
 * the same operations per sum), written to ``c`` as eppf_nrm_eig8_* reads it.
 *
 * eppf_nrm_eig8_*: the unit eigenvector of the smallest eigenvalue of each
 * lane's covariance, with the arithmetic of _normals_fast.pyx's
 * ``_smallest_eigvec`` (the closed-form eigenvalues by Newton's method on
 * 4 x^3 - 3 x = r, then the longest cross product of two rows of
 * C - lambda_min I), operation for operation. The scalar code's branches
 * become per-lane selections: a lane's Newton iterates stop moving exactly
 * when the scalar loop's would (the loop runs until every lane has stopped,
 * at most 200 steps), and the lanes that the scalar code hands to Jacobi (p
 * not > 0, nearly equal smallest eigenvalues, a zero or NaN cross product)
 * are returned as a bit mask for the caller to solve with it. ``c`` holds
 * the six distinct entries c00, c01, c02, c11, c12, c22, eight lanes each
 * (48 doubles); ``out`` gets the x, y and z components, eight lanes each
 * (24 doubles; the mask's lanes are undefined).
 *
 * Only +, -, *, / and sqrt, correctly rounded and not contracted (the build
 * passes -ffp-contract=off): each lane gives the scalar code's bits on every
 * CPU at every level. */

/* mask ? x : y, lane by lane (a mask lane is all ones or zero) */
#define EPPF_NRM_L_SEL(m, x, y) \
    ((EPPF_NRM_L_VT)((((EPPF_NRM_L_VL)(x)) & (m)) | (((EPPF_NRM_L_VL)(y)) & ~(m))))
#define EPPF_NRM_L_SQRT(v)                           \
    do {                                             \
        int l_;                                      \
        for (l_ = 0; l_ < EPPF_NRM_L_W; l_++)        \
            (v)[l_] = __builtin_sqrt((v)[l_]);       \
    } while (0)

EPPF_NRM_L_ATTR
static void EPPF_NRM_L_NAME(eppf_nrm_cov8)(const double *nb, int64_t k, double *c)
{
    int64_t i;
    int g;
    for (g = 0; g < EPPF_NRM_LANES; g += EPPF_NRM_L_W) {
        const double *px = nb + g, *py = px + EPPF_NRM_LANES * k, *pz = py + EPPF_NRM_LANES * k;
        EPPF_NRM_L_VT mx = {0.0}, my = {0.0}, mz = {0.0}, x, y, z, dk = (EPPF_NRM_L_VT){0.0} + (double)k;
        EPPF_NRM_L_VT s00 = {0.0}, s01 = {0.0}, s02 = {0.0}, s11 = {0.0}, s12 = {0.0}, s22 = {0.0};
        for (i = 0; i < k; i++) {
            __builtin_memcpy(&x, px + EPPF_NRM_LANES * i, sizeof x);
            __builtin_memcpy(&y, py + EPPF_NRM_LANES * i, sizeof y);
            __builtin_memcpy(&z, pz + EPPF_NRM_LANES * i, sizeof z);
            mx += x;
            my += y;
            mz += z;
        }
        mx /= dk;
        my /= dk;
        mz /= dk;
        for (i = 0; i < k; i++) {
            __builtin_memcpy(&x, px + EPPF_NRM_LANES * i, sizeof x);
            __builtin_memcpy(&y, py + EPPF_NRM_LANES * i, sizeof y);
            __builtin_memcpy(&z, pz + EPPF_NRM_LANES * i, sizeof z);
            x -= mx;
            y -= my;
            z -= mz;
            s00 += x * x;
            s01 += x * y;
            s02 += x * z;
            s11 += y * y;
            s12 += y * z;
            s22 += z * z;
        }
        __builtin_memcpy(c + g, &s00, sizeof s00);
        __builtin_memcpy(c + EPPF_NRM_LANES + g, &s01, sizeof s01);
        __builtin_memcpy(c + 2 * EPPF_NRM_LANES + g, &s02, sizeof s02);
        __builtin_memcpy(c + 3 * EPPF_NRM_LANES + g, &s11, sizeof s11);
        __builtin_memcpy(c + 4 * EPPF_NRM_LANES + g, &s12, sizeof s12);
        __builtin_memcpy(c + 5 * EPPF_NRM_LANES + g, &s22, sizeof s22);
    }
}

EPPF_NRM_L_ATTR
static unsigned EPPF_NRM_L_NAME(eppf_nrm_eig8)(const double *c, double *out)
{
    unsigned mask = 0;
    int g;
    for (g = 0; g < EPPF_NRM_LANES; g += EPPF_NRM_L_W) {
        EPPF_NRM_L_VT a00, a01, a02, a11, a12, a22, q, p1, d0, d1, d2, p2, p, b00, b11, b22, b01, b02, b12, r;
        EPPF_NRM_L_VT a, b, fa, fb, na, nb, x1, x2, x3, lam, m00, m11, m22;
        EPPF_NRM_L_VT c0x, c0y, c0z, c1x, c1y, c1z, c2x, c2y, c2z, n0, n1, n2, nsq, nrm;
        EPPF_NRM_L_VL bad, mva, mvb, s0, s1;
        int step, l;
        __builtin_memcpy(&a00, c + 0 * EPPF_NRM_LANES + g, sizeof a00);
        __builtin_memcpy(&a01, c + 1 * EPPF_NRM_LANES + g, sizeof a01);
        __builtin_memcpy(&a02, c + 2 * EPPF_NRM_LANES + g, sizeof a02);
        __builtin_memcpy(&a11, c + 3 * EPPF_NRM_LANES + g, sizeof a11);
        __builtin_memcpy(&a12, c + 4 * EPPF_NRM_LANES + g, sizeof a12);
        __builtin_memcpy(&a22, c + 5 * EPPF_NRM_LANES + g, sizeof a22);
        q = ((a00 + a11) + a22) / 3.0;
        p1 = ((a01 * a01) + (a02 * a02)) + (a12 * a12);
        d0 = a00 - q;
        d1 = a11 - q;
        d2 = a22 - q;
        p2 = (((d0 * d0) + (d1 * d1)) + (d2 * d2)) + (2.0 * p1);
        p = p2 / 6.0;
        EPPF_NRM_L_SQRT(p);
        bad = ~(p > 0.0);
        b00 = d0 / p;
        b11 = d1 / p;
        b22 = d2 / p;
        b01 = a01 / p;
        b02 = a02 / p;
        b12 = a12 / p;
        r = 0.5 * (((b00 * ((b11 * b22) - (b12 * b12))) - (b01 * ((b01 * b22) - (b12 * b02))))
                   + (b02 * ((b01 * b12) - (b11 * b02))));
        r = EPPF_NRM_L_SEL(r < -1.0, (EPPF_NRM_L_VT){} - 1.0, r);
        r = EPPF_NRM_L_SEL(r > 1.0, (EPPF_NRM_L_VT){} + 1.0, r);
        /* _cubic_roots */
        a = 0.8661 + (r / 6.0);
        b = -0.8661 + (r / 6.0);
        a = EPPF_NRM_L_SEL(a > 1.0, (EPPF_NRM_L_VT){} + 1.0, a);
        b = EPPF_NRM_L_SEL(b < -1.0, (EPPF_NRM_L_VT){} - 1.0, b);
        mva = mvb = (EPPF_NRM_L_VL){} - 1;
        /* two steps per test of whether any lane still moves: a lane that has
         * stopped never moves again, and 200 is even */
        for (step = 0; step < 200; step += 2) {
            long long any = 0;
            int half;
            for (half = 0; half < 2; half++) {
                fa = ((12.0 * a) * a) - 3.0;
                na = EPPF_NRM_L_SEL(fa > 0.0, a - ((((((4.0 * a) * a) - 3.0) * a) - r) / fa), a);
                mva &= na < a;
                a = EPPF_NRM_L_SEL(mva, na, a);
                fb = ((12.0 * b) * b) - 3.0;
                nb = EPPF_NRM_L_SEL(fb > 0.0, b - ((((((4.0 * b) * b) - 3.0) * b) - r) / fb), b);
                mvb &= nb > b;
                b = EPPF_NRM_L_SEL(mvb, nb, b);
            }
            for (l = 0; l < EPPF_NRM_L_W; l++)
                any |= mva[l] | mvb[l];
            if (!any)
                break;
        }
        x1 = a;
        x3 = b;
        x2 = -(x1 + x3);
        bad |= (x2 - x3) < (EPPF_NRM_GAP_RATIO * (x1 - x3));
        lam = q + ((2.0 * p) * x3);
        m00 = a00 - lam;
        m11 = a11 - lam;
        m22 = a22 - lam;
        c0x = (a01 * a12) - (a02 * m11);
        c0y = (a02 * a01) - (m00 * a12);
        c0z = (m00 * m11) - (a01 * a01);
        c1x = (a01 * m22) - (a02 * a12);
        c1y = (a02 * a02) - (m00 * m22);
        c1z = (m00 * a12) - (a01 * a02);
        c2x = (m11 * m22) - (a12 * a12);
        c2y = (a12 * a02) - (a01 * m22);
        c2z = (a01 * a12) - (m11 * a02);
        n0 = ((c0x * c0x) + (c0y * c0y)) + (c0z * c0z);
        n1 = ((c1x * c1x) + (c1y * c1y)) + (c1z * c1z);
        n2 = ((c2x * c2x) + (c2y * c2y)) + (c2z * c2z);
        s0 = (n0 >= n1) & (n0 >= n2);
        s1 = ~s0 & (n1 >= n2);
        nsq = EPPF_NRM_L_SEL(s0, n0, EPPF_NRM_L_SEL(s1, n1, n2));
        nrm = nsq;
        EPPF_NRM_L_SQRT(nrm);
        bad |= ~(nrm > 0.0);
        c0x = EPPF_NRM_L_SEL(s0, c0x, EPPF_NRM_L_SEL(s1, c1x, c2x)) / nrm;
        c0y = EPPF_NRM_L_SEL(s0, c0y, EPPF_NRM_L_SEL(s1, c1y, c2y)) / nrm;
        c0z = EPPF_NRM_L_SEL(s0, c0z, EPPF_NRM_L_SEL(s1, c1z, c2z)) / nrm;
        __builtin_memcpy(out + g, &c0x, sizeof c0x);
        __builtin_memcpy(out + EPPF_NRM_LANES + g, &c0y, sizeof c0y);
        __builtin_memcpy(out + 2 * EPPF_NRM_LANES + g, &c0z, sizeof c0z);
        for (l = 0; l < EPPF_NRM_L_W; l++)
            mask |= (unsigned)(bad[l] != 0) << (g + l);
    }
    return mask;
}

#undef EPPF_NRM_L_SEL
#undef EPPF_NRM_L_SQRT
#undef EPPF_NRM_L_NAME
#undef EPPF_NRM_L_ATTR
#undef EPPF_NRM_L_VT
#undef EPPF_NRM_L_VL
#undef EPPF_NRM_L_W
