"""The compiled step engine's kernel: one (projected) VPRK step per point, in numba.

Nothing here knows a system, a tableau or a projection by name.  The system enters as two
compiled point functions (generated from its symbolic ϑ and H by :mod:`integrators.engine`):

    ev(q, k, need, th, T, TT, dH, HH)   ϑ, ϑ_q [k, i], ∇H and, when ``need``, ϑ_qq [k, i, j], ∇²H at q
    inside(q, k) -> bool                 q is finite and inside the system's domain

with ``k`` the parameter values and every matrix flattened row-major.  The tableau is one flat
array ``[a, a_lo, abar, abar_lo, b, b_lo, d, E]`` (double + correction coefficients, the Lobatto
constraint vector d, zero when unused, and the stage-guess extrapolation E), and the projection a
tuple of codes ``(pre, pre_at, post, post_at, sigma, lobatto)`` made by
:class:`integrators.projections.Projection` from the paper's table.  So one compilation serves
every system, every tableau and every projection; only the dtype (float64 for runs, complex128
for the audit's complex-step derivatives) makes a second one.

The unknowns of a step are z = [Y_1 … Y_s, Λ (coupled projections), μ (Lobatto)] with
Y_i = h V_i the stage displacements and Λ = hλ (see integrators/projections.py for the equations,
eq:vprk_1–eq:vprk_3, eq:vprk_lobatto and the projections' eq:…_pre / eq:…_post).  Newton uses
the exact Jacobian, factorised by a small dense LU with partial pivoting and kept across
iterations and steps while it contracts.  Every decision is per point, so a point's bits never
depend on its batch, the thread count or the MPI rank count.  No fastmath.

Inside a step the kernel works on raw pointers into one scratch buffer per thread (``_at``): numba
reference-counts every array view it makes, and those atomic counts cost more than the arithmetic
of a small step; the small helpers are inlined at numba's level (profile in docs/benchmarks.md).
"""
from __future__ import annotations

import numpy as np
from numba import njit, prange, types
from numba.extending import intrinsic

_OPTS = dict(cache=True, error_model="numpy", nogil=True)

EPS = np.finfo(np.float64).eps
COMPLEX_STEP = 1e-30    # the audit's complex-step size: imaginary parts are derivatives × this
TOL = 4 * EPS           # converged when max |δ|/scale ≤ TOL
STALL = 1e-10           # ... or when below STALL and the update no longer halves (round-off floor)
STALL_COMPLEX = 1e-13   # complex step: a round-off floor counts only when it is a tight one
MAXITER = 40            # (TOL, STALL, STALL_COMPLEX, MAXITER, REFRESH: the defaults of
#                         integrators.engine.Tolerances, which the kernel takes at run time)
REFRESH = 0.01          # a fresh Jacobian when an iteration contracted by less than this factor.
#                         (0.03 suited the numpy engine, whose Jacobians cost many numpy calls; compiled, a
#                         fresh Jacobian is cheap enough that 0.01 is faster: GLRK1-none 8.0 -> 6.7 Newton
#                         iterations per step and +9 % point-steps/s, GLRK2-symmetric 7.5 -> 6.5 and +3 %, on
#                         guiding_centre_symmetric at h = 10; docs/benchmarks.md)

# where ϑ and its derivatives were last evaluated (point-buffer slots; codes of the projections)
START, MIDPOINT, END = 0, 1, 2

# offsets into the scratch buffer (see _layout) and slots of its vectors
(_Q, _TH, _T, _TT, _DH, _HH, _G, _K, _PTH, _PT, _PTT, _PDH, _PHH, _V, _Z, _ZEV, _R, _S, _PL, _PZ, _PZEV, _PR,
 _GUESS, _ZERO, _NBUF) = range(25)
(_QBAR, _PBAR, _Q0, _PB, _SY, _SG, _Q1, _P1, _M, _TL, _QH, _PH, _VF, _INC, _QN, _QCN, _PN, _PCN, _LN,
 _SYS) = range(20)
_NVEC = 20


@intrinsic
def _at(typingctx, base, off):
    """Pointer to element ``off`` (flat, C order) of an array, or ``off`` elements past a pointer."""
    if isinstance(base, types.Array):
        def codegen(context, builder, sig, args):
            ary = context.make_array(sig.args[0])(context, builder, args[0])
            return builder.gep(ary.data, [args[1]])
        return types.CPointer(base.dtype)(base, off), codegen
    if isinstance(base, types.CPointer):
        def codegen(context, builder, sig, args):
            return builder.gep(args[0], [args[1]])
        return base(base, off), codegen


@njit(**_OPTS)
def _layout(s, d, nz):
    """Offsets of the scratch buffers in one flat array, and its length."""
    dd = d * d
    sizes = (s * d, s * d, s * dd, s * dd * d, s * d, s * dd, s * d, s * dd,
             3 * d, 3 * dd, 3 * dd * d, 3 * d, 3 * dd,
             _NVEC * d, nz, nz, nz, 2 * dd, dd, d, d, d, s * d, d)
    off = [0] * (len(sizes) + 1)
    for i in range(len(sizes)):
        off[i + 1] = off[i] + sizes[i]
    return (off[0], off[1], off[2], off[3], off[4], off[5], off[6], off[7], off[8], off[9], off[10], off[11],
            off[12], off[13], off[14], off[15], off[16], off[17], off[18], off[19], off[20], off[21], off[22],
            off[23], off[24])


# -- small dense linear algebra ---------------------------------------------------------------

@njit(inline='always', **_OPTS)
def lu_factor(A, piv, n):
    """In-place LU of the n×n row-major A with partial pivoting (pivot chosen on the real part, so
    the complex-step specialisation pivots exactly as the real one).  A zero pivot is left in
    place: the solve then gives inf/NaN, which the Newton iteration reads as a failure."""
    for col in range(n):
        p = col
        best = abs(A[col * n + col].real)
        for i in range(col + 1, n):
            v = abs(A[i * n + col].real)
            if v > best:
                best, p = v, i
        piv[col] = p
        if p != col:
            for j in range(n):
                tmp = A[col * n + j]
                A[col * n + j] = A[p * n + j]
                A[p * n + j] = tmp
        inv = 1.0 / A[col * n + col]
        for i in range(col + 1, n):
            f = A[i * n + col] * inv
            A[i * n + col] = f
            if f != 0.0:
                for j in range(col + 1, n):
                    A[i * n + j] = A[i * n + j] - f * A[col * n + j]


@njit(inline='always', **_OPTS)
def lu_solve(A, piv, x, n):
    """Solve A x = b in place (x holds b on entry) with the factors of :func:`lu_factor`."""
    for i in range(n):
        p = piv[i]
        if p != i:
            tmp = x[i]
            x[i] = x[p]
            x[p] = tmp
    for i in range(n):
        acc = x[i]
        for j in range(i):
            acc = acc - A[i * n + j] * x[j]
        x[i] = acc
    for i in range(n - 1, -1, -1):
        acc = x[i]
        for j in range(i + 1, n):
            acc = acc - A[i * n + j] * x[j]
        x[i] = acc / A[i * n + i]


@njit(inline='always', **_OPTS)
def _tapply(T, v, out, d):
    """out_m = Σ_l T[l, m] v_l  (ϑ_qᵀ v)."""
    for m in range(d):
        acc = T[m] * v[0]
        for l in range(1, d):
            acc = acc + T[l * d + m] * v[l]
        out[m] = acc


@njit(inline='always', **_OPTS)
def _contract(TT, v, out, d):
    """out[m, n] = Σ_l TT[l, m, n] v_l  (∂(ϑ_qᵀ v)/∂q)."""
    dd = d * d
    for mn in range(dd):
        acc = TT[mn] * v[0]
        for l in range(1, d):
            acc = acc + TT[l * dd + mn] * v[l]
        out[mn] = acc


@njit(inline='always', **_OPTS)
def _eval(ev, k, x, need, w, L, slot, d):
    """ϑ and its derivatives at x into point slot ``slot`` (START, MIDPOINT or END)."""
    dd = d * d
    ev(x, k, need, _at(w, L[_PTH] + slot * d), _at(w, L[_PT] + slot * dd), _at(w, L[_PTT] + slot * dd * d),
       _at(w, L[_PDH] + slot * d), _at(w, L[_PHH] + slot * dd))


# -- the step's equations ---------------------------------------------------------------------

@njit(inline='always', **_OPTS)
def _main(z, jac, r, J, ev, k, h, tb, proj, d, s, w, L):
    """Residual (and Jacobian into J) of the stage equations, with the coupled projection's Λ.

    R_i = ϑ(Q_i) − p̃ − Σ_j ā_ij G_j (+ μ d_i/b_i),  Q_i = q̃ + Σ_j a_ij Y_j,  G_i = ϑ_q(Q_i)ᵀY_i − h∇H(Q_i)
    (eq:vprk_2, eq:vprk_lobatto); with a coupled projection q̃ = q̄ + Λ, p̃ = p̄ + ϑ_q(x_pre)ᵀΛ
    (eq:symmetric_projection_pre, eq:symplectic_midpoint_projection_pre) and the constraint row
    R_Λ = p_{n+1} − ϑ(q_{n+1}) with q_{n+1} = q̃ + Σ b_i Y_i + σΛ and
    p_{n+1} = p̃ + Σ b_i G_i + σ ϑ_q(x_post)ᵀΛ (the matching _post labels).
    """
    pre, pre_at, post, post_at, sig, lob = proj
    ss = s * s
    a, alo, ab, ablo = _at(tb, 0), _at(tb, ss), _at(tb, 2 * ss), _at(tb, 3 * ss)
    b, blo, dv = _at(tb, 4 * ss), _at(tb, 4 * ss + s), _at(tb, 4 * ss + 2 * s)
    dd = d * d
    ddd = dd * d
    Q, th, T, TT = _at(w, L[_Q]), _at(w, L[_TH]), _at(w, L[_T]), _at(w, L[_TT])
    dH, HH, G, K = _at(w, L[_DH]), _at(w, L[_HH]), _at(w, L[_G]), _at(w, L[_K])
    pth, pT, pTT = _at(w, L[_PTH]), _at(w, L[_PT]), _at(w, L[_PTT])
    V = L[_V]
    qbar, pbar, q0, pb = _at(w, V + _QBAR * d), _at(w, V + _PBAR * d), _at(w, V + _Q0 * d), _at(w, V + _PB * d)
    sY, sG, q1, p1 = _at(w, V + _SY * d), _at(w, V + _SG * d), _at(w, V + _Q1 * d), _at(w, V + _P1 * d)
    M, tl = _at(w, V + _M * d), _at(w, V + _TL * d)
    sd = s * d
    coupled = pre == 1
    iL = sd
    iM = sd + d if coupled else sd
    for m in range(d):
        q0[m] = qbar[m] + z[iL + m] if coupled else qbar[m]
    for i in range(s):
        for m in range(d):
            acc = a[i * s] * z[m]
            for j in range(1, s):
                acc = acc + a[i * s + j] * z[j * d + m]
            cor = alo[i * s] * z[m]
            for j in range(1, s):
                cor = cor + alo[i * s + j] * z[j * d + m]
            Q[i * d + m] = q0[m] + (acc + cor)
        ev(_at(Q, i * d), k, jac, _at(th, i * d), _at(T, i * dd), _at(TT, i * ddd), _at(dH, i * d), _at(HH, i * dd))
        Gi = _at(G, i * d)
        _tapply(_at(T, i * dd), _at(z, i * d), Gi, d)
        for m in range(d):
            Gi[m] = Gi[m] - h * dH[i * d + m]
        if jac:
            Ki = _at(K, i * dd)
            _contract(_at(TT, i * ddd), _at(z, i * d), Ki, d)
            for mn in range(dd):
                Ki[mn] = Ki[mn] - h * HH[i * dd + mn]
    for m in range(d):                     # Σ b_i Y_i and Σ b_i G_i, double + correction weights
        acc = b[0] * z[m]
        cor = blo[0] * z[m]
        accg = b[0] * G[m]
        corg = blo[0] * G[m]
        for i in range(1, s):
            acc = acc + b[i] * z[i * d + m]
            cor = cor + blo[i] * z[i * d + m]
            accg = accg + b[i] * G[i * d + m]
            corg = corg + blo[i] * G[i * d + m]
        sY[m] = acc + cor
        sG[m] = accg + corg
    Lz = _at(z, iL)
    px = START
    if coupled:
        if pre_at == MIDPOINT:             # ϑ_q at the unprojected midpoint q̄_{n+1/2}
            for m in range(d):
                M[m] = q0[m] + 0.5 * sY[m]
            _eval(ev, k, M, jac, w, L, MIDPOINT, d)
            px = MIDPOINT
        _tapply(_at(pT, px * dd), Lz, pb, d)
        for m in range(d):
            pb[m] = pbar[m] + pb[m]
    else:
        for m in range(d):
            pb[m] = pbar[m]
    for i in range(s):
        for m in range(d):
            acc = ab[i * s] * G[m]
            for j in range(1, s):
                acc = acc + ab[i * s + j] * G[j * d + m]
            cor = ablo[i * s] * G[m]
            for j in range(1, s):
                cor = cor + ablo[i * s + j] * G[j * d + m]
            rr = th[i * d + m] - pb[m] - (acc + cor)
            if lob:
                rr = rr + z[iM + m] * (dv[i] / b[i])
            r[i * d + m] = rr
    if coupled:
        for m in range(d):
            q1[m] = q0[m] + sY[m] + sig * Lz[m]
        _eval(ev, k, q1, jac, w, L, END, d)
        pp = END if post_at == END else px
        _tapply(_at(pT, pp * dd), Lz, tl, d)
        for m in range(d):
            p1[m] = pb[m] + sG[m] + sig * tl[m]
            r[iL + m] = p1[m] - pth[END * d + m]
    if lob:
        for m in range(d):
            acc = dv[0] * z[m]
            for i in range(1, s):
                acc = acc + dv[i] * z[i * d + m]
            r[iM + m] = acc
    if not jac:
        return
    # -- the exact Jacobian ------------------------------------------------------------------
    nz = sd + (d if coupled else 0) + (d if lob else 0)
    for i in range(nz * nz):
        J[i] = 0.0
    Sx, S1 = _at(w, L[_S]), _at(w, L[_S] + dd)
    if coupled and pre_at == MIDPOINT:
        _contract(_at(pTT, MIDPOINT * ddd), Lz, Sx, d)        # ∂(ϑ_q(M)ᵀΛ)/∂M
    if coupled and post_at == END:
        _contract(_at(pTT, END * ddd), Lz, S1, d)             # ∂(ϑ_q(q1)ᵀΛ)/∂q1
    for i in range(s):
        for j in range(s):
            aij, abij = a[i * s + j], ab[i * s + j]
            for m in range(d):
                for n in range(d):
                    B = aij * T[i * dd + m * d + n] - abij * T[j * dd + n * d + m]
                    for l in range(s):
                        c = ab[i * s + l] * a[l * s + j]
                        if c != 0.0:
                            B = B - c * K[l * dd + m * d + n]
                    if coupled and pre_at == MIDPOINT:
                        B = B - (0.5 * b[j]) * Sx[m * d + n]
                    J[(i * d + m) * nz + j * d + n] = B
    if coupled:
        Tx = _at(pT, px * dd)
        T1 = _at(pT, END * dd)
        Tp = T1 if post_at == END else Tx
        spost = S1 if post_at == END else Sx
        upost = (1.0 + sig) if post_at == END else 1.0      # ∂x_post/∂Λ
        cpost = 1.0 if post_at == END else 0.5              # ∂x_post/∂Y_j = cpost b_j
        for m in range(d):
            for n in range(d):
                dpb = Tx[n * d + m]                         # ∂p̃/∂Λ = ϑ_q(x_pre)ᵀ (+ S_x at the midpoint)
                if pre_at == MIDPOINT:
                    dpb = dpb + Sx[m * d + n]
                for i in range(s):
                    B = T[i * dd + m * d + n]
                    for l in range(s):
                        if ab[i * s + l] != 0.0:
                            B = B - ab[i * s + l] * K[l * dd + m * d + n]
                    J[(i * d + m) * nz + iL + n] = B - dpb
                KS = b[0] * K[m * d + n]
                for l in range(1, s):
                    KS = KS + b[l] * K[l * dd + m * d + n]
                J[(iL + m) * nz + iL + n] = (dpb + sig * Tp[n * d + m] + (sig * upost) * spost[m * d + n]) + KS \
                    - (1.0 + sig) * T1[m * d + n]
                for j in range(s):
                    KB = b[0] * a[j] * K[m * d + n]
                    for l in range(1, s):
                        KB = KB + b[l] * a[l * s + j] * K[l * dd + m * d + n]
                    ey = sig * cpost * spost[m * d + n]
                    if pre_at == MIDPOINT:
                        ey = ey + 0.5 * Sx[m * d + n]
                    J[(iL + m) * nz + j * d + n] = KB + b[j] * T[j * dd + n * d + m] + b[j] * ey - b[j] * T1[m * d + n]
    if lob:
        for i in range(s):
            for m in range(d):
                J[(i * d + m) * nz + iM + m] = dv[i] / b[i]
                J[(iM + m) * nz + i * d + m] = dv[i]


@njit(inline='always', **_OPTS)
def _post(z, jac, r, J, ev, k, sig, d, w, L):
    """The consecutive projection: solve ϑ(q̂ + σΛ) = p̂ + σ ϑ_q(q̂ + σΛ)ᵀΛ for Λ
    (eq:orthogonal_projection, eq:symplectic_projection_post) with q̂, p̂ the step's q̄ + ΣbY, p̄ + ΣbG."""
    dd = d * d
    V = L[_V]
    qh, ph, q1, p1, tl = _at(w, V + _QH * d), _at(w, V + _PH * d), _at(w, V + _Q1 * d), _at(w, V + _P1 * d), \
        _at(w, V + _TL * d)
    th1, T1, TT1 = _at(w, L[_PTH] + END * d), _at(w, L[_PT] + END * dd), _at(w, L[_PTT] + END * dd * d)
    for m in range(d):
        q1[m] = qh[m] + sig * z[m]
    _eval(ev, k, q1, jac, w, L, END, d)
    _tapply(T1, z, tl, d)
    for m in range(d):
        p1[m] = ph[m] + sig * tl[m]
        r[m] = p1[m] - th1[m]
    if jac:
        S1 = _at(w, L[_S] + dd)
        _contract(TT1, z, S1, d)
        for m in range(d):
            for n in range(d):
                J[m * d + n] = sig * (T1[n * d + m] - T1[m * d + n]) + (sig * sig) * S1[m * d + n]


@njit(**_OPTS)
def _newton(mode, z, zev, r, scale, nz, J, piv, known, cplx, ev, k, h, tb, proj, d, s, w, L, cfg):
    """Newton's method with the exact Jacobian, kept while it contracts (per point).

    ``mode`` 0 solves the step's equations (:func:`_main`), 1 the consecutive projection
    (:func:`_post`).  The Jacobian is evaluated and factorised at the first iteration (unless
    ``known``: J and piv hold the last step's factors) and again after an iteration that shrank the
    update by less than REFRESH.  Converged when max |δ|/scale ≤ TOL, or ≤ STALL once the update
    stops halving; for complex z the imaginary part, read as a derivative, must pass the same test.
    Returns (converged, iterations); the solution is ``zev``, the last iterate at which the
    residual was evaluated, and every buffer the equations fill holds that evaluation.  The
    tolerances are runtime data, ``cfg`` = [TOL, STALL, STALL_COMPLEX, MAXITER, REFRESH, ACCEPT]
    (:class:`integrators.engine.Tolerances`); with ACCEPT a finite iterate that has not converged
    after MAXITER iterations is taken (GeometricIntegrators.jl's stopping rule).
    """
    tol, stall, refresh = cfg[0], cfg[2] if cplx else cfg[1], cfg[4]
    previous = np.inf
    stale = not known
    its = 0
    for _ in range(int(cfg[3])):
        for i in range(nz):
            zev[i] = z[i]
        if mode == 0:
            _main(z, stale, r, J, ev, k, h, tb, proj, d, s, w, L)
        else:
            _post(z, stale, r, J, ev, k, proj[4], d, w, L)
        if stale:
            lu_factor(J, piv, nz)
        lu_solve(J, piv, r, nz)                    # r is now −δ
        size = 0.0
        nan = False
        finite = True
        for i in range(nz):
            z[i] = z[i] - r[i]
            v = abs(r[i].real) / scale[i]
            if cplx:
                v = max(v, abs(r[i].imag) / (COMPLEX_STEP * scale[i]))
            if v != v:
                nan = True
            elif v > size:
                size = v
            if not np.isfinite(z[i]):
                finite = False
        its += 1
        if nan or not finite or not np.isfinite(size):
            return False, its
        theta = size / previous if np.isfinite(previous) else np.inf
        if (size <= tol) or (size <= stall and np.isfinite(theta) and theta > 0.5):
            return True, its
        stale = np.isfinite(theta) and theta > refresh
        previous = size
    return cfg[5] != 0 and its > 0, its


# -- one step of one point --------------------------------------------------------------------

@njit(**_OPTS)
def _first_guess(ev, k, q, h, Y, d, s, w, L, ipiv):
    """Stage displacements h·q̇(q_n) at every stage, q̇ solving Ω̄ q̇ = ∇H
    (eq:euler_lagrange_equations); zero where that is not finite."""
    _eval(ev, k, q, False, w, L, START, d)
    T, dH, PL, v = _at(w, L[_PT]), _at(w, L[_PDH]), _at(w, L[_PL]), _at(w, L[_V] + _VF * d)
    for i in range(d):
        for j in range(d):
            PL[i * d + j] = T[j * d + i] - T[i * d + j]
        v[i] = dH[i]
    lu_factor(PL, ipiv, d)
    lu_solve(PL, ipiv, v, d)
    good = True
    for i in range(d):
        if not np.isfinite(v[i]):
            good = False
    for i in range(s):
        for m in range(d):
            Y[i * d + m] = h * v[m] if good else 0.0


@njit(**_OPTS)
def _prepare(ev, k, q, p, lam, proj, d, w, L):
    """q̄, p̄ where Ψ_h starts: projected methods start on the constraint p_n = ϑ(q_n); the symplectic
    projection first adds the last step's Λ_n (eq:symplectic_projection_pre); ϑ_q(q_n) stays in
    the START slot for the symmetric projection's perturbation."""
    pre, post = proj[0], proj[2]
    V = L[_V]
    qbar, pbar, tl = _at(w, V + _QBAR * d), _at(w, V + _PBAR * d), _at(w, V + _TL * d)
    pth, pT = _at(w, L[_PTH]), _at(w, L[_PT])
    if post:
        _eval(ev, k, q, False, w, L, START, d)
    for m in range(d):
        qbar[m] = q[m] + lam[m] if pre == 2 else q[m]
        pbar[m] = pth[m] if post else p[m]
    if pre == 2:
        _tapply(pT, lam, tl, d)
        for m in range(d):
            pbar[m] = pbar[m] + tl[m]


@njit(**_OPTS)
def _attempt(reuse, guess, mu0, cplx, ev, inside, k, h, tb, proj, d, s, nz, w, L, rw, ipiv, pt_ptrs, cfg):
    """One step of a point from the stage guess (and μ guess); commits the new state when it
    succeeds.  Returns (ok, iterations)."""
    q, p, lam, qc, pc, Ys, mus, lu, piv, have = pt_ptrs
    pre, pre_at, post, post_at, sig, lob = proj
    V = L[_V]
    qbar, pbar, sY, sG = _at(w, V + _QBAR * d), _at(w, V + _PBAR * d), _at(w, V + _SY * d), _at(w, V + _SG * d)
    p1 = _at(w, V + _P1 * d)
    z, zev, r = _at(w, L[_Z]), _at(w, L[_ZEV]), _at(w, L[_R])
    scale, pscale, qr = _at(rw, 0), _at(rw, nz), _at(rw, nz + d)
    sd = s * d
    coupled = pre == 1
    iL = sd
    iM = sd + d if coupled else sd
    _prepare(ev, k, q, p, lam, proj, d, w, L)
    for i in range(sd):
        z[i] = guess[i]
    for m in range(d):
        sc = max(abs(q[m]), 1.0)                # every unknown relative to its coordinate's size
        if not np.isfinite(sc):
            sc = 1.0
        for i in range(nz // d):
            scale[i * d + m] = sc
        if coupled:
            z[iL + m] = lam[m]
        if lob:
            z[iM + m] = mu0[m]
            sc = max(abs(pbar[m]), 1.0)
            scale[iM + m] = sc if np.isfinite(sc) else 1.0
    ok, its = _newton(0, z, zev, r, scale, nz, lu, piv, reuse and have[0] != 0, cplx, ev, k, h, tb, proj, d, s, w, L,
                      cfg)
    inc, pn, ln = _at(w, V + _INC * d), _at(w, V + _PN * d), _at(w, V + _LN * d)
    if coupled:                                 # Ψ_h and Λ solved together
        for m in range(d):
            Lm = zev[iL + m]
            inc[m] = (Lm + sY[m]) + sig * Lm
            pn[m] = p1[m]
            ln[m] = Lm
    elif post:                                  # Ψ_h, then the projection
        qh, ph, sYs = _at(w, V + _QH * d), _at(w, V + _PH * d), _at(w, V + _SYS * d)
        pz, pzev, pr = _at(w, L[_PZ]), _at(w, L[_PZEV]), _at(w, L[_PR])
        for m in range(d):
            sYs[m] = sY[m]
            qh[m] = qbar[m] + sY[m]
            ph[m] = pbar[m] + sG[m]
            pz[m] = lam[m]
            sc = max(abs(qh[m]), 1.0)
            pscale[m] = sc if np.isfinite(sc) else 1.0
        ok1, its1 = _newton(1, pz, pzev, pr, pscale, d, _at(w, L[_PL]), ipiv, False, cplx, ev, k, h, tb, proj, d, s,
                            w, L, cfg)
        ok = ok and ok1
        its += its1
        for m in range(d):
            shift = lam[m] + sYs[m] if pre == 2 else sYs[m]
            inc[m] = shift + sig * pzev[m]
            pn[m] = p1[m]
            ln[m] = pzev[m]
    else:
        for m in range(d):
            inc[m] = sY[m]
            ln[m] = 0.0
    qn, qcn, pcn = _at(w, V + _QN * d), _at(w, V + _QCN * d), _at(w, V + _PCN * d)
    for m in range(d):                          # compensated summation of the increments
        y = inc[m] + qc[m]
        t = q[m] + y
        qcn[m] = y - (t - q[m])
        qn[m] = t
        if post:
            pcn[m] = pc[m]
        else:
            y = sG[m] + pc[m]
            t = p[m] + y
            pcn[m] = y - (t - p[m])
            pn[m] = t
        qr[m] = qn[m].real
    ok = ok and inside(qr, k)
    for m in range(d):
        if not (np.isfinite(pn[m]) and np.isfinite(ln[m])):
            ok = False
    if ok:
        for m in range(d):
            q[m] = qn[m]
            qc[m] = qcn[m]
            p[m] = pn[m]
            pc[m] = pcn[m]
            lam[m] = ln[m]
            if lob:
                mus[m] = zev[iM + m]
        for i in range(sd):
            Ys[i] = zev[i]
    return ok, its


@njit(**_OPTS)
def _step(t_next, cplx, ev, inside, k, h, tb, proj, d, s, nz, w, L, rw, ipiv, pt_ptrs, flags, tb_ptr, counts, cfg):
    """Advance one point by one step.  A step that fails from the extrapolated guess (and the last
    step's Jacobian) is tried once more from h·q̇(q_n) with a fresh Jacobian; a point that still
    fails (Newton does not converge, a value is not finite, q leaves the domain) is frozen at its
    last good state with its breakdown time set to ``t_next``."""
    q, Ys, mus = pt_ptrs[0], pt_ptrs[5], pt_ptrs[6]
    have = pt_ptrs[9]
    hist, live = flags
    ss = s * s
    E = _at(tb, 4 * ss + 3 * s)
    guess = _at(w, L[_GUESS])
    fresh = hist[0] == 0
    if fresh:
        _first_guess(ev, k, q, h, guess, d, s, w, L, ipiv)
    else:                                       # Lagrange extrapolation of the last step's stages
        for i in range(s):
            for m in range(d):
                acc = E[i * s] * Ys[m]
                for j in range(1, s):
                    acc = acc + E[i * s + j] * Ys[j * d + m]
                guess[i * d + m] = acc
    ok, its = _attempt(True, guess, mus, cplx, ev, inside, k, h, tb, proj, d, s, nz, w, L, rw, ipiv, pt_ptrs, cfg)
    counts[0] += its
    if not ok and not fresh:
        _first_guess(ev, k, q, h, guess, d, s, w, L, ipiv)
        ok, its = _attempt(False, guess, _at(w, L[_ZERO]), cplx, ev, inside, k, h, tb, proj, d, s, nz, w, L, rw, ipiv,
                           pt_ptrs, cfg)
        counts[0] += its
    have[0] = 1 if ok else 0
    if ok:
        counts[1] += 1
        hist[0] = 1
    else:
        live[0] = 0
        tb_ptr[0] = t_next
    return ok


@njit(**_OPTS)
def _block(W, RW, IP, CN, lo, hi, ev, inside, kp, h, tb, proj, t0, first, nsteps, cplx, st, d, s, nz, L, cfg):
    """Points lo … hi − 1 of the state through ``nsteps`` steps, with the thread's scratch arrays.

    The scratch arrays are arguments (not locals) on purpose: the caller holds them for the whole
    call, while numba would free a local array after its last use as an array, i.e. while the raw
    pointers taken from it are still in use.
    """
    q, p, Lam, qc, pc, Y, mu, hist, live, tbrk, itn, stp, lu, piv, have = st
    w, rw, ipiv, counts = _at(W, 0), _at(RW, 0), _at(IP, 0), _at(CN, 0)
    for pt in range(lo, hi):
        if live[pt] == 0:
            continue
        pt_ptrs = (_at(q, pt * d), _at(p, pt * d), _at(Lam, pt * d), _at(qc, pt * d), _at(pc, pt * d),
                   _at(Y, pt * s * d), _at(mu, pt * d), _at(lu, pt * nz * nz), _at(piv, pt * nz), _at(have, pt))
        flags = (_at(hist, pt), _at(live, pt))
        CN[0] = 0
        CN[1] = 0
        for j in range(nsteps):
            if not _step(t0 + (first + j) * h, cplx, ev, inside, kp, h, tb, proj, d, s, nz, w, L, rw, ipiv,
                         pt_ptrs, flags, _at(tbrk, pt), counts, cfg):
                break
        itn[pt] += CN[0]
        stp[pt] += CN[1]


@njit(parallel=True, **_OPTS)
def advance(ev, inside, k, tab, proj, h, t0, first, nsteps, cplx, block, st, dim, tolerances):
    """Advance every live point of the state tuple ``st`` by ``nsteps`` steps, the step numbered
    ``first`` aiming at t0 + first·h.  Points are taken ``block`` at a time, blocks spread over
    the threads; a point's steps never depend on its block, its thread or its neighbours.

    st = (q, p, Lam, q_comp, p_comp, Y, mu, have_history, live, breakdown_time, iterations, steps,
    lu, piv, have_lu), the boolean flags viewed as uint8.  ``tolerances``: Newton's [TOL, STALL,
    STALL_COMPLEX, MAXITER, REFRESH, ACCEPT] as float64 (:class:`integrators.engine.Tolerances`).
    """
    q, Y, lu = st[0], st[5], st[12]
    n = q.shape[0]
    d = len(dim)           # ``dim`` is a tuple of d zeros: d is a compile-time constant, one compilation
    #                        per dimension, and the compiler unrolls the loops over coordinates
    s = Y.shape[1]
    nz = lu.shape[1]
    L = _layout(s, d, nz)
    kp, tb, cfg = _at(k, 0), _at(tab, 0), _at(tolerances, 0)
    nblocks = (n + block - 1) // block
    for bi in prange(nblocks):
        W = np.zeros(L[_NBUF], q.dtype)
        RW = np.zeros(nz + 2 * d)
        IP = np.zeros(d, np.int64)
        CN = np.zeros(2, np.int64)
        _block(W, RW, IP, CN, bi * block, min(n, (bi + 1) * block), ev, inside, kp, h, tb, proj, t0, first, nsteps,
               cplx, st, d, s, nz, L, cfg)


@njit(**_OPTS)
def _probe(W, zz, r, J, ev, k, tab, proj, h, q, p, lam, jac, s, L):
    d = q.shape[0]
    w = _at(W, 0)
    _prepare(ev, _at(k, 0), _at(q, 0), _at(p, 0), _at(lam, 0), proj, d, w, L)
    _main(_at(zz, 0), jac, _at(r, 0), _at(J, 0), ev, _at(k, 0), h, _at(tab, 0), proj, d, s, w, L)


@njit(**_OPTS)
def probe(ev, k, tab, proj, h, q, p, lam, z, jac):
    """The step's residual at z (and its Jacobian when ``jac``) for one point (q, p, Λ): the equations
    Newton solves, for tests (the Jacobian against complex-step differences of the residual)."""
    d = q.shape[0]
    nz = z.shape[0]
    s = 0
    for cand in range(1, 9):                    # the flat tableau holds 5 s² + 3 s numbers
        if 5 * cand * cand + 3 * cand == tab.shape[0]:
            s = cand
    L = _layout(s, d, nz)
    W = np.zeros(L[_NBUF], z.dtype)
    r = np.zeros(nz, z.dtype)
    J = np.zeros(nz * nz, z.dtype)
    zz = z.copy()
    _probe(W, zz, r, J, ev, k, tab, proj, h, q, p, lam, jac, s, L)
    return r, J.reshape((nz, nz))
