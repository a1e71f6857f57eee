"""The post term of the projections solved after Ψ_h: the paper's (:func:`project`,
eq:orthogonal_projection, eq:symplectic_projection_post) and the contract a projection's own
compiled post term follows (:func:`post_term` chooses between them when the kernel is compiled;
docs/engine.md, "A projection of one's own")."""
from __future__ import annotations

from numba import njit, types
from numba.extending import intrinsic, models, overload, register_model

from ..projections import END
from ..simd import at, ld, st
from .records import _OPTS
from .linalg import apply, contract, rounding, transpose_apply
from .equations import evaluate, exact_points


@njit(inline='always', **_OPTS)
def project(z, jac, r, J, ev, k, sig, d, w, S):
    """The post term of the consecutive projections (standard, symplectic): ϑ(q̂ + σΛ) = p̂ + σ
    ϑ_q(q̂ + σΛ)ᵀΛ, to be solved for Λ (eq:orthogonal_projection, eq:symplectic_projection_post).

    The contract of every post term (a projection's ``post_term``; :func:`_newton` calls it in
    MODE_POST, d unknowns): from the core's unprojected end point q̂, p̂ (``S.qh``, ``S.ph``, the
    step's q̄ + ΣbY, p̄ + ΣbG) and the iterate Λ = ``z``, write p_{n+1} into ``S.p1``, the d
    residuals into ``r`` and, when ``jac``, their Jacobian ∂r/∂Λ row-major into ``J``; in plain
    doubles it may write what forming p_{n+1} dropped into ``S.pcn`` (the kernel sets it to 0
    first).  The kernel then takes q_{n+1} = q̂ + σΛ (by compensated summation) and p_{n+1} (with
    that term as its compensation term), and the next step starts from them.  What a post term may use,
    all public (integrators.kernel, integrators.simd): ``evaluate(ev, k, x, jac, w, S, slot, d)``, ϑ
    and its derivatives at x into a point slot (START, MIDPOINT, END; ``S.q1`` is scratch for such an
    x); ``transpose_apply`` (ϑ_qᵀv), ``apply`` (ϑ_q v), ``contract`` (∂(ϑ_qᵀv)/∂q), ``rounding``
    (TwoSum's error); ``at``, ``ld``, ``st`` of simd.  In plain doubles (``exact_points``)
    ``S.qhe`` and ``S.phe`` hold what rounding q̂ and p̂ to double dropped: a post term resolves Λ
    below an ulp of q when its residual sees its sums exactly, as this one does (ϑ at q̂ + σΛ as
    ϑ + ϑ_q e, e that error plus its own sum's, :func:`rounding`; p̂ + σϑ_qᵀΛ with its errors
    added, which are p_{n+1}'s compensation term); one that does not still converges, to an ulp of q."""
    dd = d * d
    qh, ph, q1, p1, tl = at(w, S.qh), at(w, S.ph), at(w, S.q1), at(w, S.p1), at(w, S.tl)
    th1, T1, TT1 = at(w, S.pth + END * d), at(w, S.pT + END * dd), at(w, S.pTT + END * dd * d)
    exact = exact_points(ld(qh, 0))
    e1, te = at(w, S.eQ), at(w, S.tE)
    for m in range(d):
        q1m = ld(qh, m) + sig * ld(z, m)
        st(q1, m, q1m)
        if exact:
            st(e1, m, ld(w, S.qhe + m) + rounding(ld(qh, m), sig * ld(z, m), q1m))
    evaluate(ev, k, q1, jac, w, S, END, d)
    transpose_apply(T1, z, tl, d)
    if exact:
        apply(T1, e1, te, d)
    for m in range(d):
        p1m = ld(ph, m) + sig * ld(tl, m)
        st(p1, m, p1m)
        rm = p1m - ld(th1, m)
        if exact:
            pe = ld(w, S.phe + m) + rounding(ld(ph, m), sig * ld(tl, m), p1m)
            st(w, S.pcn + m, pe)
            rm = (rm + pe) - ld(te, m)
        st(r, m, rm)
    if jac:
        S1 = at(w, S.S + dd)
        contract(TT1, z, S1, d)
        for m in range(d):
            for n in range(d):
                st(J, m * d + n, sig * (ld(T1, n * d + m) - ld(T1, m * d + n)) + (sig * sig) * ld(S1, m * d + n))


PAPER = 0      # ``post`` of the paper's projections: :func:`project`, compiled in (a function argument
#                would key the kernel on a Python object, which numba's cache cannot find again)


def post_term(P, z, jac, r, J, ev, d, w, S):
    """The post term of the step's :class:`Step` record ``P``: its ``post`` (PAPER: :func:`project`;
    else a projection's own compiled function, called as :func:`project` is), with the parameters
    ``P.k`` and the weight σ = ``P.plan.sigma``; chosen when the kernel is compiled."""


@overload(post_term, inline="always")
def _post_term(P, z, jac, r, J, ev, d, w, S):
    post = P[P.fields.index("post")]
    if isinstance(post, types.Integer):
        return lambda P, z, jac, r, J, ev, d, w, S: project(z, jac, r, J, ev, P.k, P.plan.sigma, d, w, S)
    if isinstance(post, PostTerm):
        fn = post.fn
        return lambda P, z, jac, r, J, ev, d, w, S: fn(z, jac, r, J, ev, P.k, P.plan.sigma, d, w, S)
    return lambda P, z, jac, r, J, ev, d, w, S: P.post(z, jac, r, J, ev, P.k, P.plan.sigma, d, w, S)


class PostTerm(types.Type):
    """A projection's own post term as a type with no value: the kernel calls ``fn`` (a compiled
    function) where it reads ``P.post``, and nothing of the function is held in a value, so a kernel
    compiled for it holds no address of this process and numba can cache it (:func:`token`)."""

    def __init__(self, fn):
        self.fn = fn
        f = fn.py_func
        super().__init__(name=f"PostTerm({f.__module__}.{f.__qualname__}@{id(fn):x})")

    def __reduce__(self):               # a cache index's key: another process finds no such function
        return types.Opaque, (f"gone {self.name}",)


register_model(PostTerm)(models.OpaqueModel)


def token(fn):
    """An intrinsic ``t()`` giving the :class:`PostTerm` of the compiled post term ``fn``: what a
    generated kernel entry hands the kernel as its ``post`` (:mod:`integrators.kernel.custom`)."""
    ty = PostTerm(fn)

    @intrinsic
    def t(typingctx):
        return ty(), lambda context, builder, sig, args: context.get_constant_null(ty)
    return t
