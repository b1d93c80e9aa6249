"""Symmetric LDL^T of the KKT matrix (eq. 27) in envelope storage, without pivoting.

The KKT matrix ``J = [[H, C^T], [C, 0]]`` (``H`` the Hessian of the
Lagrangian, ``C`` the constraint Jacobian) is symmetric.  In scaled
coordinates (``H_s = D H D``, ``C_s = E C D``: the dof scales ``D`` and
the constraint rows normalised by ``E``) it is factorised in its penalised
form ::

    K = [[H_s + rho C_s^T C_s, C_s^T], [C_s, 0]],   rho = PENALTY * max|H_s|,

which has the same solution as ``J`` (the right-hand side gets
``rho C_s^T`` times the constraint part; the penalty vanishes where the
constraints hold) and, near a stable equilibrium, a positive definite
leading block.  Ordered by height along the robot (:func:`core.linalg._ordering.level_order`
for the coordinates) with every multiplier right after the last coordinate
its constraint touches, every leading block of ``K`` is then itself a
KKT matrix with a positive definite Hessian: the factorisation
``K = L D L^T`` with 1x1 pivots exists without pivoting, ``D`` has ``nq``
positive and ``nc`` negative entries (the inertia of ``J`` exactly when the
equilibrium is stable, ``inertia``).  Fill stays within the envelope of
that order (each column from its diagonal to its last entry), about a third
of the band that a pivoted banded LU fills: for two segments 0.29 million
multiply-adds against about 1.8 million (``N kl (kl + ku)``) for LAPACK's
``dgbtrf`` on the same matrix (measured in isolation: 2.5 times faster,
assembly included).

There is no pivoting, so every factorisation measures its growth
(``max_i sum_k L_ik^2 |d_k|`` against ``max |K|``); above ``MAX_GROWTH``,
or on a zero or non-finite pivot, :meth:`EnvelopeKKT.factor` returns None
and the caller uses the pivoted banded LU (:mod:`core.linalg._kkt`).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ._ordering import level_order

__all__ = ["EnvelopeKKT", "EnvelopeLDL", "PENALTY", "MAX_GROWTH", "ldl_solve_vector"]

# rho = PENALTY * max|H_s|: 1 keeps the factor as accurate as the pivoted LU (relative
# difference of the solutions ~1e-12 at the default robots' equilibria); 10 loses 1-2 digits
PENALTY = 1.0
# growth of the factorisation (relative to max|K|) above which it is not used
MAX_GROWTH = 1e6
_OUTSIDE = -1.0  # the growth a factorisation reports for non-zeros outside the pattern


def _ldl_order(model, keep):
    """New position of every KKT unknown: coordinates in level order, multipliers after theirs."""
    nq, N = model.nq, model.N
    lv = level_order(model)
    q_order = lv[lv < nq]
    pos = np.empty(nq)
    pos[q_order] = np.arange(nq)
    ip, ix = model.csc_indptr, model.csc_indices
    cols = np.repeat(np.arange(N), np.diff(ip))
    sel = keep & (ix >= nq) & (cols < nq)  # C entries: row nq + r, column q
    r, q = ix[sel] - nq, cols[sel]
    key = np.full(model.nc, -1.0)
    np.maximum.at(key, r, pos[q])
    if np.any(key < 0):
        raise ValueError("a constraint row without coordinates")
    order = np.lexsort((np.arange(N), np.concatenate([pos, key + 0.5])))
    new = np.empty(N, dtype=np.int64)
    new[order] = np.arange(N)
    return order.astype(np.int64), new


# the integer arrays of a pattern, packed in one array (fewer arguments for compiled calls):
# sections, in this order, after a header of their offsets and the sizes below
_SECTIONS = ("new", "ck", "cr", "cq", "last", "colptr", "first", "rowptr", "ent_k", "ent_pos",
             "ent_i", "ent_j", "rptr", "pa", "pb", "pr", "ppos", "dropped")
(_NEW, _CK, _CR, _CQ, _LAST, _COLPTR, _FIRST, _ROWPTR, _ENT_K, _ENT_POS, _ENT_I, _ENT_J, _RPTR,
 _PA, _PB, _PR, _PPOS, _DROPPED) = range(len(_SECTIONS))
_NS = len(_SECTIONS)
# header: offsets of the sections (_NS + 1), then nq, N, nc, size (envelope), rsize (by rows)
_HEAD = _NS + 1 + 5


class EnvelopeKKT:
    """Order, envelope and scatter maps of one model's penalised KKT matrix (built once).

    ``coordinates_only``: the leading block ``H_s + rho C_s^T C_s`` alone
    (the coordinates in level order), for :meth:`positive_definite`.
    """

    def __init__(self, model, coordinates_only=False):
        """Build from ``model``'s KKT pattern (its structural non-zeros)."""
        nq, N, nc = model.nq, model.N, model.nc
        keep = model.structural_nonzeros()
        order, new = _ldl_order(model, keep)
        ip, ix = model.csc_indptr, model.csc_indices
        cols = np.repeat(np.arange(N), np.diff(ip)).astype(np.int64)
        rows = ix.astype(np.int64)
        k_all = np.flatnonzero(keep)
        n = N
        if coordinates_only:  # the coordinates in the same relative order, first
            k_all = k_all[(rows[k_all] < nq) & (cols[k_all] < nq)]
            rank = np.empty(nq, dtype=np.int64)
            rank[np.argsort(new[:nq], kind="stable")] = np.arange(nq)
            new = np.concatenate([rank, nq + np.arange(nc)])
            order, n = np.argsort(new[:nq]), nq
        a, b = new[rows[k_all]], new[cols[k_all]]
        low = a >= b  # one triangle of J (with the diagonal)
        ent_k, ent_a, ent_b = k_all[low], a[low], b[low]
        # C entries by constraint row (for E, C_s^T y and the penalty pairs)
        ck = np.flatnonzero(keep & (rows >= nq) & (cols < nq))
        cr, cq = rows[ck] - nq, cols[ck]
        o = np.lexsort((new[cq], cr))
        ck, cr, cq = ck[o], cr[o], cq[o]
        rptr = np.searchsorted(cr, np.arange(nc + 1))
        # every pair (i, j) of one row's entries, row by row, i-major (the penalty pairs)
        length = np.diff(rptr)
        row = np.repeat(np.arange(nc), length * length)
        k = np.arange(row.size) - np.repeat(np.cumsum(length * length) - length * length,
                                            length * length)
        ii = rptr[row] + k // length[row]
        jj = rptr[row] + k % length[row]
        m = new[cq[ii]] >= new[cq[jj]]
        pa, pb = ii[m], jj[m]
        # envelope: column j holds rows j..last[j] (last non-decreasing: no fill outside)
        lastnz = np.arange(n)
        np.maximum.at(lastnz, ent_b, ent_a)
        np.maximum.at(lastnz, new[cq[pb]], new[cq[pa]])
        last = np.maximum.accumulate(lastnz)
        colptr = np.concatenate([[0], np.cumsum(last - np.arange(n) + 1)])
        first = np.searchsorted(last, np.arange(n))  # row i of L: columns first[i]..i-1
        rowptr = np.concatenate([[0], np.cumsum(np.arange(n) - first)])
        secs = dict(new=new, ck=ck, cr=cr, cq=cq, last=last, colptr=colptr, first=first,
                    rowptr=rowptr, ent_k=ent_k, ent_pos=colptr[ent_b] + ent_a - ent_b,
                    ent_i=rows[ent_k], ent_j=cols[ent_k], rptr=rptr, pa=pa, pb=pb, pr=cr[pa],
                    ppos=colptr[new[cq[pb]]] + new[cq[pa]] - new[cq[pb]],
                    dropped=np.flatnonzero(~keep))
        parts = [np.asarray(secs[k], dtype=np.int64) for k in _SECTIONS]
        offs = _HEAD + np.concatenate([[0], np.cumsum([len(x) for x in parts])])
        self.size, self.rsize = int(colptr[-1]), int(rowptr[-1])
        head = np.concatenate([offs, [nq, n, nc, self.size, self.rsize]])
        self.ints = np.concatenate([head] + parts).astype(np.int64)
        self.ints.flags.writeable = False
        self.order, self.new = order, new
        self.nq, self.N, self.nc, self.nnz, self.n = nq, N, nc, model.nnz, n
        self.coordinates_only = coordinates_only
        self.flops = float(((last - np.arange(n)) ** 2).sum() / 2)  # multiply-adds

    def _factorise(self, J, D, penalty, shift, rows):
        """Assemble and factorise ``J``'s values: ``(fv, rho, growth)`` (see :func:`_factorise`).

        ``rows``: room for ``L`` by rows in ``fv`` (the solves need it).
        """
        if J.nnz != self.nnz:  # before the compiled call indexes J.data by the pattern
            raise ValueError("matrix does not have the model's KKT pattern")
        fv = np.empty(self.nc + self.size + (self.rsize if rows else 0) + self.n)
        rho, growth = _factorise(J.data, D, self.ints, fv, float(penalty), float(shift), rows)
        if growth == _OUTSIDE:
            raise ValueError("matrix has non-zeros outside the model's pattern")
        return fv, rho, growth

    def factor(self, J, D):
        """``EnvelopeLDL`` of ``J`` (CSC, the model's pattern; ``D`` the dof scales), or None."""
        if self.coordinates_only:
            raise ValueError("a pattern of the coordinates only factorises no KKT matrix")
        fv, rho, growth = self._factorise(J, D, PENALTY, 0.0, True)
        if not growth <= MAX_GROWTH:  # also NaN: a zero or non-finite pivot
            return None
        return EnvelopeLDL(self, J.data, D, fv, rho, growth)

    def positive_definite(self, J, D, penalty, shift):
        """Is ``H_s - s I + rho C_s^T C_s`` positive definite? (``coordinates_only`` pattern).

        ``rho = penalty * max|H_s|``, ``s = shift * max|H_s|``: every pivot of
        its LDL^T positive, the test a Cholesky factorisation makes (the
        same operations, without the square roots).
        """
        if not self.coordinates_only:
            raise ValueError("positive_definite needs a pattern of the coordinates only")
        fv, _, growth = self._factorise(J, D, penalty, shift, False)
        return bool(growth == growth and np.all(fv[-self.n:] > 0.0))


class EnvelopeLDL:
    """One factorisation; ``solve`` takes and returns unknowns in the model's order."""

    def __init__(self, pattern, data, D, fv, rho, growth):
        """Keep the factors ``fv`` of the matrix with values ``data``."""
        self.p, self.data, self.D, self.fv, self.rho, self.growth = (
            pattern, data, np.ascontiguousarray(D, dtype=float), fv, rho, growth)
        d = fv[-pattern.n:]
        self.inertia = (int(np.sum(d > 0)), int(np.sum(d < 0)))

    def args(self):
        """The arguments of the compiled solves before the right-hand side."""
        return self.data, self.D, self.p.ints, self.fv, self.rho

    def solve(self, b):
        """Solve ``J x = b`` (``b``: vector or matrix of columns)."""
        b = np.ascontiguousarray(b, dtype=float)
        if b.ndim == 1:
            return ldl_solve_vector(self.data, self.D, self.p.ints, self.fv, self.rho, b)
        return _solve_columns(self.data, self.D, self.p.ints, self.fv, self.rho, b)


@njit(cache=True, nogil=True, inline="always")
def _sec(ints, k):
    return ints[ints[k]:ints[k + 1]]


@njit(cache=True, nogil=True)
def _views(ints, fv):
    """The arrays inside ``fv``: ``E``, ``env`` (``L`` by columns), ``renv`` (by rows), ``d``.

    ``renv`` is empty when ``fv`` has no room for it (a positive-definiteness test).
    """
    nc, size, rsize, n = ints[_NS + 3], ints[_NS + 4], ints[_NS + 5], ints[_NS + 2]
    if fv.shape[0] < nc + size + rsize + n:
        rsize = 0
    return fv[:nc], fv[nc:nc + size], fv[nc + size:nc + size + rsize], fv[nc + size + rsize:]


@njit(cache=True, nogil=True)
def _factorise(data, D, ints, fv, penalty, shift, rows):
    """Assemble, factorise (``rows``: ``L`` by rows too); returns ``rho`` and the relative growth.

    ``shift * max|H_s|`` is subtracted from the coordinates' diagonal.  The
    growth is NaN after a zero or non-finite pivot, ``_OUTSIDE`` when ``data``
    has a non-zero outside the pattern.
    """
    for k in _sec(ints, _DROPPED):
        if data[k] != 0.0:
            return 0.0, _OUTSIDE
    nq = ints[_NS + 1]
    E, env, renv, d = _views(ints, fv)
    ref, kmax = _assemble(data, D, nq, E, env, _sec(ints, _ENT_K), _sec(ints, _ENT_POS),
                          _sec(ints, _ENT_I), _sec(ints, _ENT_J), _sec(ints, _CK),
                          _sec(ints, _CQ), _sec(ints, _RPTR), _sec(ints, _PA), _sec(ints, _PB),
                          _sec(ints, _PR), _sec(ints, _PPOS), penalty)
    last, colptr = _sec(ints, _LAST), _sec(ints, _COLPTR)
    rho = penalty * ref
    if shift != 0.0:
        new = _sec(ints, _NEW)
        for i in range(nq):
            env[colptr[new[i]]] -= shift * ref
    g = _factor(env, last, colptr, d, rows, _sec(ints, _FIRST), _sec(ints, _ROWPTR), renv)
    if not g <= np.inf:
        return rho, np.nan
    return rho, g / kmax if kmax > 0.0 else np.nan


@njit(cache=True, nogil=True)
def _assemble(data, D, nq, E, env, ent_k, ent_pos, ent_i, ent_j, ck, cq, rptr, pa, pb, pr, ppos,
              penalty):
    """Scaled, penalised ``K`` into ``env`` (envelope), ``E``; returns max|H_s|, max|K|."""
    nc = rptr.shape[0] - 1
    for r in range(nc):
        s = 0.0
        for t in range(rptr[r], rptr[r + 1]):
            v = data[ck[t]] * D[cq[t]]
            s += v * v
        E[r] = 1.0 / np.sqrt(s) if s > 0.0 else 1.0
    ref = 0.0
    for t in range(ent_k.shape[0]):
        i, j = ent_i[t], ent_j[t]
        if i < nq and j < nq:
            v = abs(data[ent_k[t]] * D[i] * D[j])
            if v > ref:
                ref = v
    rho = penalty * ref
    env[:] = 0.0
    for t in range(ent_k.shape[0]):
        i, j = ent_i[t], ent_j[t]
        si = D[i] if i < nq else E[i - nq]
        sj = D[j] if j < nq else E[j - nq]
        env[ent_pos[t]] += data[ent_k[t]] * si * sj
    for t in range(pa.shape[0]):
        a, b, r = pa[t], pb[t], pr[t]
        env[ppos[t]] += rho * E[r] * E[r] * (data[ck[a]] * D[cq[a]]) * (data[ck[b]] * D[cq[b]])
    kmax = 0.0
    for t in range(env.shape[0]):
        if abs(env[t]) > kmax:
            kmax = abs(env[t])
    return ref, kmax


@njit(cache=True, nogil=True, fastmath=True)
def _factor(env, last, colptr, d, rows, first, rowptr, renv):
    """In-place ``K = L D L^T`` (unit ``L`` below the diagonal of ``env``); the growth, or NaN.

    ``rows``: ``L`` by rows into ``renv`` too (row ``i``: columns ``first[i]..i-1``), for
    the forward sweep.
    """
    N = last.shape[0]
    u = np.empty(N)
    lc = np.empty(N)
    rowsum = np.zeros(N)
    for j in range(N):
        base = colptr[j]
        n = last[j] - j
        dj = env[base]
        d[j] = dj
        if not (dj != 0.0 and abs(dj) < np.inf):
            return np.nan
        inv = 1.0 / dj
        for t in range(1, n + 1):
            v = env[base + t]
            u[t] = v
            lc[t] = v * inv
            env[base + t] = v * inv
            rowsum[j + t] += abs(v * v * inv)
            if rows:
                renv[rowptr[j + t] - first[j + t] + j] = v * inv
        for t in range(1, n + 1):
            cb = colptr[j + t] - t
            f = u[t]
            a = env[cb + t:cb + n + 1]
            b = lc[t:n + 1]
            for s in range(a.shape[0]):
                a[s] -= b[s] * f
    g = 0.0
    for i in range(N):
        v = rowsum[i] + abs(d[i])
        if not v <= g:
            g = v
    return g


@njit(cache=True, nogil=True)
def _rhs(data, D, E, rho, nq, new, ck, cr, cq, b, y):
    """Right-hand side of the scaled, penalised system, in the factor's order, into ``y``."""
    N = b.shape[0]
    t = b[:nq].copy()
    for k in range(ck.shape[0]):
        r = cr[k]
        t[cq[k]] += rho * E[r] * E[r] * data[ck[k]] * b[nq + r]
    for i in range(nq):
        y[new[i]] = D[i] * t[i]
    for r in range(N - nq):
        y[new[nq + r]] = E[r] * b[nq + r]


@njit(cache=True, nogil=True, fastmath=True)
def _sweeps(env, renv, d, last, colptr, first, rowptr, x):
    """``x <- K^{-1} x`` with the factors: dot-product sweeps (by rows, then by columns)."""
    N = x.shape[0]
    for i in range(N):
        o = rowptr[i] - first[i]
        s = 0.0
        for k in range(first[i], i):
            s += renv[o + k] * x[k]
        x[i] -= s
    for j in range(N - 1, -1, -1):
        o = colptr[j] - j
        s = 0.0
        for i in range(j + 1, last[j] + 1):
            s += env[o + i] * x[i]
        x[j] = x[j] / d[j] - s


@njit(cache=True, nogil=True, fastmath=True)
def _sweeps8(env, renv, d, last, colptr, first, rowptr, X):
    """The sweeps of :func:`_sweeps` on eight columns at once (``X``: N x 8, by rows)."""
    N = X.shape[0]
    acc = np.empty(8)
    for i in range(N):
        o = rowptr[i] - first[i]
        for c in range(8):
            acc[c] = 0.0
        for k in range(first[i], i):
            lv = renv[o + k]
            for c in range(8):
                acc[c] += lv * X[k, c]
        for c in range(8):
            X[i, c] -= acc[c]
    for j in range(N - 1, -1, -1):
        o = colptr[j] - j
        for c in range(8):
            acc[c] = 0.0
        for i in range(j + 1, last[j] + 1):
            lv = env[o + i]
            for c in range(8):
                acc[c] += lv * X[i, c]
        inv = 1.0 / d[j]
        for c in range(8):
            X[j, c] = X[j, c] * inv - acc[c]


@njit(cache=True, nogil=True)
def _unscale(D, E, nq, new, y, x):
    """The solution in the model's order and units into ``x``."""
    N = y.shape[0]
    for i in range(nq):
        x[i] = D[i] * y[new[i]]
    for r in range(N - nq):
        x[nq + r] = E[r] * y[new[nq + r]]


@njit(cache=True, nogil=True)
def ldl_solve_vector(data, D, ints, fv, rho, b):
    """Solve ``J x = b`` for one vector ``b`` (model's order) with an ``EnvelopeLDL``'s arrays."""
    nq = ints[_NS + 1]
    E, env, renv, d = _views(ints, fv)
    new = _sec(ints, _NEW)
    y = np.empty(b.shape[0])
    _rhs(data, D, E, rho, nq, new, _sec(ints, _CK), _sec(ints, _CR), _sec(ints, _CQ), b, y)
    _sweeps(env, renv, d, _sec(ints, _LAST), _sec(ints, _COLPTR), _sec(ints, _FIRST),
            _sec(ints, _ROWPTR), y)
    x = np.empty(b.shape[0])
    _unscale(D, E, nq, new, y, x)
    return x


@njit(cache=True, nogil=True)
def _solve_columns(data, D, ints, fv, rho, B):
    """Solve ``J X = B`` for the columns of ``B``: eight at a time, one or two left one by one."""
    nq = ints[_NS + 1]
    E, env, renv, d = _views(ints, fv)
    new, ck, cr, cq = _sec(ints, _NEW), _sec(ints, _CK), _sec(ints, _CR), _sec(ints, _CQ)
    last, colptr, first, rowptr = (_sec(ints, _LAST), _sec(ints, _COLPTR), _sec(ints, _FIRST),
                                   _sec(ints, _ROWPTR))
    N, M = B.shape
    X = np.empty((N, M))
    y = np.empty(N)
    x = np.empty(N)
    c0 = 0
    while c0 < M:
        w = min(8, M - c0)
        if w <= 2:  # a sweep of eight columns costs about three of one
            for c in range(c0, M):
                _rhs(data, D, E, rho, nq, new, ck, cr, cq, np.ascontiguousarray(B[:, c]), y)
                _sweeps(env, renv, d, last, colptr, first, rowptr, y)
                _unscale(D, E, nq, new, y, x)
                X[:, c] = x
            break
        Y = np.zeros((N, 8))
        for c in range(c0, c0 + w):
            _rhs(data, D, E, rho, nq, new, ck, cr, cq, np.ascontiguousarray(B[:, c]), y)
            Y[:, c - c0] = y
        _sweeps8(env, renv, d, last, colptr, first, rowptr, Y)
        for c in range(c0, c0 + w):
            _unscale(D, E, nq, new, np.ascontiguousarray(Y[:, c - c0]), x)
            X[:, c] = x
        c0 += w
    return X
