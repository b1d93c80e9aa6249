"""Reference solutions for a horizontally cantilevered planar beam.

Pure numpy/scipy (no project imports).  Used to validate the ANCF
(gradient-deficient, cubic Hermite) finite-element code.

Setup
-----
Planar, ``x`` horizontal, ``z`` up.  Beam of reference length ``L`` clamped at
``x = 0``: ``r(0) = (0, 0)``, ``r'(0)`` parallel to ``+x`` with its LENGTH free
(the clamp fixes the direction only).  Distributed weight ``w`` [N/m of
reference length] in ``-z``, tip force ``P`` [N] in ``-z`` at ``x = L``.
Bending stiffness ``EI = k_b`` [N m^2], tensile stiffness ``k_t`` [N].
All "drops" returned here are positive downward.

1. Small deflection (linear Euler-Bernoulli)
-------------------------------------------
``drop = w L^4 / (8 EI) + P L^3 / (3 EI)``.

2. Classical inextensible elastica (Kirchhoff rod, ``M = EI theta'``)
--------------------------------------------------------------------
Arc length ``s in [0, L]``, ``theta`` = tangent angle from ``+x`` (ccw).
The moment of the loads beyond ``s`` about the section point is
``-int_s^L w (x(t) - x(s)) dt - P (x(L) - x(s))``; equilibrium of the piece
``[s, L]`` gives ``M(s) = EI theta'(s)`` equal to this, and differentiating,
``EI theta'' = V(s) cos(theta)`` with ``V(s) = w (L - s) + P``,
``theta(0) = 0``, ``theta'(L) = 0``; ``x' = cos(theta)``, ``z' = sin(theta)``.
Solved (dimensionless, ``xi = s/L``) with ``scipy.integrate.solve_bvp``.

3. Continuum limit of the model's own energy (docs/model.md, section 3)
-----------------------------------------------------------------------
Position field ``r(x) in R^2``, ``x in [0, L]`` reference coordinate::

    Pi[r] = int_0^L 1/2 (kt eps^2 + kb |r''|^2) dx - int_0^L f.r dx - F.r(L)
    eps = (r'.r' - 1)/2,   f = (0, -w),   F = (0, -P).

With ``N = kt eps r'`` (``d(eps)/d(r') = r'``) and ``M = kb r''``::

    dPi = int N.dr' + M.dr'' - f.dr dx - F.dr(L)
        = int (M'' - N' - f).dr dx
          + [(N - M').dr]_0^L + [M.dr']_0^L - F.dr(L)

Euler-Lagrange (4th order vector ODE)::

    (kb r'')'' - (kt eps r')' = f
    i.e.  kb r'''' = f + kt (eps' r' + eps r''),   eps' = r'.r''

Boundary conditions:

* ``x = 0``: ``r = 0`` (``dr = 0``, essential); ``r'_z = 0`` (essential,
  direction clamp); ``dr'_x`` is free, so the natural condition
  ``M_x(0) = kb r''_x(0) = 0``.
* ``x = L``: ``dr'`` free -> ``kb r''(L) = 0``; ``dr(L)`` free ->
  ``(N - M')(L) = F``, i.e. ``(kt eps r' - kb r''')(L) = (0, -P)``.

Dimensionless form (``x = L xi``, ``r = L rho``, primes now d/dxi)::

    rho'''' = fhat + beta (eps' rho' + eps rho''),
    beta = kt L^2 / kb,  fhat = (0, -a),  a = w L^3 / kb,  b = P L^2 / kb,
    xi=0: rho = 0, rho'_z = 0, rho''_x = 0
    xi=1: rho'' = 0, beta eps rho' - rho''' = (0, -b)

solved as an 8-unknown first-order system
``y = [rho, rho', rho'', rho''']`` with analytic Jacobians
(``method="cartesian"``).

Equivalent reduced form (``method="polar"``): the EL equation is a
divergence, ``(N - M')' = -f``, so with the tip condition
``N - M' = n(x) := (0, -P - w (L - x))`` exactly, i.e.
``kb r''' = kt eps r' - n(x)`` (3rd order).  Writing
``r' = (1+e) t``, ``t = (cos th, sin th)``, ``nu = (-sin th, cos th)``:
``r'' = e' t + (1+e) th' nu``,
``r''' = (e'' - (1+e) th'^2) t + (2 e' th' + (1+e) th'') nu``, and projecting
on ``t``/``nu`` (``V = P + w (L - x)``)::

    kb (e'' - (1+e) th'^2) = kt eps (1+e) + V sin th,  eps = e + e^2/2
    kb (2 e' th' + (1+e) th'') = V cos th

BCs: ``x=0``: ``r = 0``, ``th = 0``, ``r''_x = e' = 0``; ``x=L``: ``e' = th' = 0``.
For ``e -> 0`` the second equation is the elastica ``EI th'' = V cos th``.
This form computes ``eps`` without cancellation and is used for very large
``kt`` (kt -> inf convergence checks); both forms agree to ~1e-12.  This is the limit
to which an exact-quadrature cubic-Hermite (gradient-deficient ANCF)
discretisation of the same energy converges.  For ``kt -> inf`` (``eps -> 0``,
``|r'| = 1``, ``|r''| = curvature``) it reduces to the elastica; for finite
``kt`` the beam is slightly softer (the axial tension near the clamp stretches
it; ``|r''|^2`` also contains the stretch-gradient term).  Note: for very
large ``beta`` the axial boundary layers at the ends have width
``~ L / sqrt(beta)`` and the solver needs correspondingly more nodes.
"""

from __future__ import annotations

import time

import numpy as np
from scipy.integrate import solve_bvp
from scipy.optimize import brentq

G_STD = 9.81

__all__ = [
    "small_deflection_tip_drop",
    "elastica_tip",
    "elastica_solution",
    "spec_continuum_tip",
    "spec_continuum_solution",
    "tip_mass_for_drop_fraction",
    "project_case_parameters",
]


# --------------------------------------------------------------------------
# 1. Linear Euler-Bernoulli
# --------------------------------------------------------------------------
def small_deflection_tip_drop(L, EI, w, P):
    """Linear cantilever tip drop (positive downward)."""
    return w * L**4 / (8.0 * EI) + P * L**3 / (3.0 * EI)


# --------------------------------------------------------------------------
# helpers
# --------------------------------------------------------------------------
def _continuation(solve_at, y_guess_fn, lam_targets_min_step=1e-4):
    """Load continuation: solve_at(lam, (xi, y)) -> sol or None.

    Tries the full load first from the analytic guess; on failure subdivides
    the load path adaptively, re-using the previous converged solution.
    """
    sol = solve_at(1.0, y_guess_fn(1.0))
    if sol is not None:
        return sol
    lam, step = 0.0, 0.25
    prev = None
    while lam < 1.0:
        lam_new = min(1.0, lam + step)
        guess = y_guess_fn(lam_new) if prev is None else (prev.x, prev.y)
        s = solve_at(lam_new, guess)
        if s is None:
            step *= 0.5
            if step < lam_targets_min_step:
                raise RuntimeError("load continuation failed at lambda=%g" % lam_new)
            continue
        prev, lam = s, lam_new
        step = min(2.0 * step, 0.5)
    return prev


# --------------------------------------------------------------------------
# 2. Inextensible elastica
# --------------------------------------------------------------------------
def _elastica_bvp(a, b, guess, tol, max_nodes):
    # y = [theta, theta', X, Z]; theta'' = (a (1-xi) + b) cos(theta)
    def fun(xi, y):
        th = y[0]
        V = a * (1.0 - xi) + b
        return np.vstack((y[1], V * np.cos(th), np.cos(th), np.sin(th)))

    def fun_jac(xi, y):
        th = y[0]
        V = a * (1.0 - xi) + b
        n = xi.size
        J = np.zeros((4, 4, n))
        J[0, 1] = 1.0
        J[1, 0] = -V * np.sin(th)
        J[2, 0] = -np.sin(th)
        J[3, 0] = np.cos(th)
        return J

    def bc(ya, yb):
        return np.array([ya[0], yb[1], ya[2], ya[3]])

    def bc_jac(ya, yb):
        Ja = np.zeros((4, 4))
        Jb = np.zeros((4, 4))
        Ja[0, 0] = 1.0
        Jb[1, 1] = 1.0
        Ja[2, 2] = 1.0
        Ja[3, 3] = 1.0
        return Ja, Jb

    xi0, y0 = guess
    sol = solve_bvp(fun, bc, xi0, y0, fun_jac=fun_jac, bc_jac=bc_jac,
                    tol=tol, bc_tol=tol, max_nodes=max_nodes)
    return sol if sol.status == 0 else None


def _linear_theta_guess(a, b, xi):
    """Linear (small-deflection) theta, theta', X, Z on the mesh xi."""
    # theta' = -int_xi^1 (a(1-t)+b) dt = -(a (1-xi)^2/2 + b (1-xi))
    u = 1.0 - xi
    dth = -(a * u**2 / 2.0 + b * u)
    # theta = int_0^xi theta'
    th = -(a * (1.0 - u**3) / 6.0 + b * (1.0 - u**2) / 2.0)
    # Z = int_0^xi theta ; X = xi
    Z = -(a * (xi - (1.0 - u**4) / 4.0) / 6.0 + b * (xi - (1.0 - u**3) / 3.0) / 2.0)
    return th, dth, xi.copy(), Z


def elastica_solution(L, EI, w, P, n_mesh=201, tol=1e-10, max_nodes=200000):
    """Solve the inextensible elastica; returns the scipy BVP solution.

    Dimensionless: xi = s/L, y = [theta, dtheta/dxi, x/L, z/L].
    """
    a = w * L**3 / EI
    b = P * L**2 / EI
    xi = np.linspace(0.0, 1.0, n_mesh)

    def guess(lam):
        th, dth, X, Z = _linear_theta_guess(lam * a, lam * b, xi)
        # keep the initial angle guess within a sensible range
        scale = min(1.0, 1.2 / max(1e-300, np.max(np.abs(th))))
        th, dth = th * scale, dth * scale
        dxi = np.diff(xi) * 0.5
        X = np.concatenate(([0.0], np.cumsum(dxi * (np.cos(th[1:]) + np.cos(th[:-1])))))
        Z = np.concatenate(([0.0], np.cumsum(dxi * (np.sin(th[1:]) + np.sin(th[:-1])))))
        return xi, np.vstack((th, dth, X, Z))

    return _continuation(lambda lam, g: _elastica_bvp(lam * a, lam * b, g, tol, max_nodes), guess)


def elastica_tip(L, EI, w, P, n_mesh=201, tol=1e-10, max_nodes=200000):
    """Inextensible elastica tip: returns (x_tip, drop), drop positive downward."""
    sol = elastica_solution(L, EI, w, P, n_mesh=n_mesh, tol=tol, max_nodes=max_nodes)
    yb = sol.y[:, -1]
    return float(yb[2] * L), float(-yb[3] * L)


# --------------------------------------------------------------------------
# 3. Continuum limit of the spec energy
# --------------------------------------------------------------------------
def _spec_bvp(beta, a, b, guess, tol, max_nodes):
    # y = [X, Z, X1, Z1, X2, Z2, X3, Z3] = [rho, rho', rho'', rho''']
    def fun(xi, y):
        r1 = y[2:4]
        r2 = y[4:6]
        r3 = y[6:8]
        eps = 0.5 * (r1[0] ** 2 + r1[1] ** 2 - 1.0)
        deps = r1[0] * r2[0] + r1[1] * r2[1]
        r4 = beta * (deps * r1 + eps * r2)
        r4[1] -= a
        return np.vstack((r1, r2, r3, r4))

    def fun_jac(xi, y):
        n = xi.size
        r1 = y[2:4]
        r2 = y[4:6]
        eps = 0.5 * (r1[0] ** 2 + r1[1] ** 2 - 1.0)
        deps = r1[0] * r2[0] + r1[1] * r2[1]
        J = np.zeros((8, 8, n))
        for i in range(6):
            J[i, i + 2] = 1.0
        for i in range(2):
            for j in range(2):
                dij = 1.0 if i == j else 0.0
                # d/d rho'_j of (deps rho'_i + eps rho''_i)
                J[6 + i, 2 + j] = beta * (r2[j] * r1[i] + deps * dij + r2[i] * r1[j])
                # d/d rho''_j
                J[6 + i, 4 + j] = beta * (r1[j] * r1[i] + eps * dij)
        return J

    def bc(ya, yb):
        epsb = 0.5 * (yb[2] ** 2 + yb[3] ** 2 - 1.0)
        return np.array([
            ya[0], ya[1], ya[3], ya[4],
            yb[4], yb[5],
            beta * epsb * yb[2] - yb[6],
            beta * epsb * yb[3] - yb[7] + b,
        ])

    def bc_jac(ya, yb):
        Ja = np.zeros((8, 8))
        Jb = np.zeros((8, 8))
        Ja[0, 0] = Ja[1, 1] = Ja[2, 3] = Ja[3, 4] = 1.0
        Jb[4, 4] = Jb[5, 5] = 1.0
        epsb = 0.5 * (yb[2] ** 2 + yb[3] ** 2 - 1.0)
        X1, Z1 = yb[2], yb[3]
        Jb[6, 2] = beta * (X1 * X1 + epsb)
        Jb[6, 3] = beta * (Z1 * X1)
        Jb[6, 6] = -1.0
        Jb[7, 2] = beta * (X1 * Z1)
        Jb[7, 3] = beta * (Z1 * Z1 + epsb)
        Jb[7, 7] = -1.0
        return Ja, Jb

    xi0, y0 = guess
    sol = solve_bvp(fun, bc, xi0, y0, fun_jac=fun_jac, bc_jac=bc_jac,
                    tol=tol, bc_tol=tol, max_nodes=max_nodes)
    return sol if sol.status == 0 else None


def _spec_polar_bvp(beta, a, b, guess, tol, max_nodes):
    # y = [X, Z, e, theta, p, k];  rho' = (1+e)(cos th, sin th), p = e', k = th'
    def fun(xi, y):
        X, Z, e, th, p, k = y
        rho = 1.0 + e
        eps = e + 0.5 * e * e
        c, s = np.cos(th), np.sin(th)
        V = a * (1.0 - xi) + b
        return np.vstack((rho * c, rho * s, p, k,
                          rho * k * k + beta * eps * rho + V * s,
                          (V * c - 2.0 * p * k) / rho))

    def fun_jac(xi, y):
        X, Z, e, th, p, k = y
        rho = 1.0 + e
        eps = e + 0.5 * e * e
        c, s = np.cos(th), np.sin(th)
        V = a * (1.0 - xi) + b
        J = np.zeros((6, 6, xi.size))
        J[0, 2], J[0, 3] = c, -rho * s
        J[1, 2], J[1, 3] = s, rho * c
        J[2, 4] = 1.0
        J[3, 5] = 1.0
        J[4, 2] = k * k + beta * (rho * rho + eps)
        J[4, 3] = V * c
        J[4, 5] = 2.0 * rho * k
        J[5, 2] = -(V * c - 2.0 * p * k) / rho**2
        J[5, 3] = -V * s / rho
        J[5, 4] = -2.0 * k / rho
        J[5, 5] = -2.0 * p / rho
        return J

    def bc(ya, yb):
        return np.array([ya[0], ya[1], ya[3], ya[4], yb[4], yb[5]])

    def bc_jac(ya, yb):
        Ja = np.zeros((6, 6))
        Jb = np.zeros((6, 6))
        Ja[0, 0] = Ja[1, 1] = Ja[2, 3] = Ja[3, 4] = 1.0
        Jb[4, 4] = Jb[5, 5] = 1.0
        return Ja, Jb

    xi0, y0 = guess
    sol = solve_bvp(fun, bc, xi0, y0, fun_jac=fun_jac, bc_jac=bc_jac,
                    tol=tol, bc_tol=tol, max_nodes=max_nodes)
    return sol if sol.status == 0 else None


def _spec_guess_from_elastica(esol, a, b, xi):
    """Initial guess [rho, rho', rho'', rho'''] from an elastica solution."""
    y = esol.sol(xi)
    th, dth, X, Z = y
    ddth = (a * (1.0 - xi) + b) * np.cos(th)
    c, s = np.cos(th), np.sin(th)
    return np.vstack((
        X, Z,
        c, s,
        -dth * s, dth * c,
        -ddth * s - dth**2 * c, ddth * c - dth**2 * s,
    ))


def spec_continuum_solution(L, kt, kb, w, P, method="auto", n_mesh=401,
                            tol=1e-10, max_nodes=100000):
    """Solve the Euler-Lagrange BVP of the spec energy; returns scipy solution.

    method:
      "cartesian": the full 8-unknown system, xi = x/L,
                   y = [r/L, dr/dx, L d2r/dx2, L^2 d3r/dx3].
      "polar":     the same BVP after using the exact first integral
                   ``kt eps r' - kb r''' = (0, -P - w (L - x))`` and writing
                   ``r' = (1+e)(cos th, sin th)`` (6 unknowns
                   ``[x/L, z/L, e, th, L e', L th']``).  Avoids the round-off
                   in ``eps = (|r'|^2 - 1)/2`` that limits the cartesian form
                   for very large ``beta = kt L^2/kb`` (kt -> inf checks).
      "auto":      cartesian for beta <= 5e4, polar above.
    The returned solution has an extra attribute ``method``.
    """
    beta = kt * L**2 / kb
    a = w * L**3 / kb
    b = P * L**2 / kb
    if method == "auto":
        method = "cartesian" if beta <= 5e4 else "polar"
    if method not in ("cartesian", "polar"):
        raise ValueError(method)
    # the elastica (exact kt -> inf limit) is the initial guess
    esol = elastica_solution(L, kb, w, P, tol=min(1e-6, 1e2 * tol))
    xi = np.linspace(0.0, 1.0, n_mesh)
    # refine the initial mesh near the ends (axial boundary layers ~ 1/sqrt(beta))
    bl = min(0.1, 5.0 / np.sqrt(beta))
    xi = np.unique(np.concatenate((xi, np.linspace(0, bl, 60), np.linspace(1 - bl, 1, 60))))

    if method == "cartesian":
        def solver(lam, g):
            return _spec_bvp(beta, lam * a, lam * b, g, tol, max_nodes)

        y_el = _spec_guess_from_elastica(esol, a, b, xi)

        def lin_guess(lam):
            th, dth, X, Z = _linear_theta_guess(lam * a, lam * b, xi)
            ddth = lam * (a * (1.0 - xi) + b)
            return xi, np.vstack((X, Z, np.ones_like(xi), th, np.zeros_like(xi), dth,
                                  np.zeros_like(xi), ddth))
    else:
        def solver(lam, g):
            return _spec_polar_bvp(beta, lam * a, lam * b, g, tol, max_nodes)

        th, dth, X, Z = esol.sol(xi)
        e = -(a * (1.0 - xi) + b) * np.sin(th) / beta   # tension / kt, leading order
        y_el = np.vstack((X, Z, e, th, np.gradient(e, xi), dth))

        def lin_guess(lam):
            th, dth, X, Z = _linear_theta_guess(lam * a, lam * b, xi)
            zero = np.zeros_like(xi)
            return xi, np.vstack((X, Z, zero, th, zero, dth))

    sol = solver(1.0, (xi, y_el))
    if sol is None:
        # fall back to continuation in load from the linear state
        sol = _continuation(solver, lin_guess)
    sol.method = method
    return sol


def spec_continuum_tip(L, kt, kb, w, P, method="auto", n_mesh=401, tol=1e-10,
                       max_nodes=100000):
    """Continuum limit of the spec energy: returns (x_tip, drop), drop > 0 down.

    See :func:`spec_continuum_solution` for ``method``.
    """
    sol = spec_continuum_solution(L, kt, kb, w, P, method=method, n_mesh=n_mesh,
                                  tol=tol, max_nodes=max_nodes)
    yb = sol.y[:, -1]
    return float(yb[0] * L), float(-yb[1] * L)


# --------------------------------------------------------------------------
# helpers for the actual test case
# --------------------------------------------------------------------------
def project_case_parameters(lam=1.0, k_lam=576.94, dk=28.9, l0=0.0963, D_a=0.01790,
                            rho_lin=0.20, g=G_STD):
    """Parameters (L, kt, kb, w) of the project test case (lam = 1).

    kt = (576.94 lam + 28.9) l0, kb = D_a^2 l0 lam (576.94 lam + 28.9) / 8,
    w = 0.20 * 9.81 (per unit reference length).
    """
    k = k_lam * lam + dk
    return dict(L=l0, kt=k * l0, kb=D_a**2 * l0 * lam * k / 8.0, w=rho_lin * g)


def tip_mass_for_drop_fraction(L, EI, w, fraction, g=G_STD, model="elastica",
                               kt=None, xtol=1e-12):
    """Tip mass m (P = m g) giving drop = fraction * L for the chosen model.

    model: "elastica" (default), "spec" (needs kt) or "linear".
    """
    def drop(m):
        P = m * g
        if model == "elastica":
            return elastica_tip(L, EI, w, P)[1]
        if model == "spec":
            return spec_continuum_tip(L, kt, EI, w, P)[1]
        if model == "linear":
            return small_deflection_tip_drop(L, EI, w, P)
        raise ValueError(model)

    target = fraction * L
    if drop(0.0) >= target:
        raise ValueError("self weight alone already exceeds the target drop")
    hi = max(1e-6, 3.0 * EI * target / L**3 / g)  # linear estimate
    while drop(hi) < target:
        hi *= 2.0
    return brentq(lambda m: drop(m) - target, 0.0, hi, xtol=xtol, rtol=1e-13)


# --------------------------------------------------------------------------
# self-check
# --------------------------------------------------------------------------
def _timed(fn, *args, **kw):
    t0 = time.perf_counter()
    out = fn(*args, **kw)
    return out, time.perf_counter() - t0


if __name__ == "__main__":
    p = project_case_parameters()
    L, kt, kb, w = p["L"], p["kt"], p["kb"], p["w"]
    print("test case: L=%.6g m  kt=%.8g N  kb=%.8g N m^2  w=%.6g N/m  beta=kt L^2/kb=%.6g"
          % (L, kt, kb, w, kt * L**2 / kb))

    # (a) tiny loads
    wt, Pt = w * 1e-4, 1e-5
    lin = small_deflection_tip_drop(L, kb, wt, Pt)
    (xe, de), te = _timed(elastica_tip, L, kb, wt, Pt)
    (xs, ds), ts = _timed(spec_continuum_tip, L, kt, kb, wt, Pt)
    print("\n(a) tiny load: linear %.10e  elastica %.10e (rel %.2e, %.3fs)  "
          "spec %.10e (rel %.2e, %.3fs)" % (lin, de, de / lin - 1, te, ds, ds / lin - 1, ts))

    # (b) moderate load, kt -> large
    Pm = 0.1
    (xe, de), te = _timed(elastica_tip, L, kb, w, Pm)
    print("\n(b) moderate P=%.3g N: elastica x_tip=%.10g drop=%.10g (%.3fs)" % (Pm, xe, de, te))
    for fac in (1.0, 1e1, 1e2, 1e3, 1e4, 1e6):
        for meth in ("cartesian", "polar"):
            if meth == "cartesian" and fac > 1e2:
                continue  # cartesian form: round-off / mesh growth at huge beta
            (xs, ds), ts = _timed(spec_continuum_tip, L, kt * fac, kb, w, Pm, method=meth)
            print("    kt*%-6g %-9s spec x_tip=%.12g drop=%.12g  diff %+.6f %%  (%.3fs)"
                  % (fac, meth, xs, ds, 100 * (ds / de - 1), ts))

    # (c) tip mass giving elastica drop = 35% L
    m, tm = _timed(tip_mass_for_drop_fraction, L, kb, w, 0.35)
    P = m * G_STD
    (xe, de), te = _timed(elastica_tip, L, kb, w, P)
    (xs, ds), ts = _timed(spec_continuum_tip, L, kt, kb, w, P, method="cartesian")
    (xp, dp), tp = _timed(spec_continuum_tip, L, kt, kb, w, P, method="polar")
    lin = small_deflection_tip_drop(L, kb, w, P)
    print("\n(c) tip mass for elastica drop 35%% L: m=%.10g kg (P=%.10g N), root find %.2fs"
          % (m, P, tm))
    print("    linear   drop=%.10g m (%.4f L)" % (lin, lin / L))
    print("    elastica x_tip=%.10g drop=%.10g m (%.6f L)  %.3fs" % (xe, de, de / L, te))
    print("    spec(c)  x_tip=%.10g drop=%.10g m (%.6f L)  %.3fs" % (xs, ds, ds / L, ts))
    print("    spec(p)  x_tip=%.10g drop=%.10g m (%.6f L)  %.3fs" % (xp, dp, dp / L, tp))
    print("    spec vs elastica: drop %+.4f %%, x_tip %+.4f %%"
          % (100 * (ds / de - 1), 100 * (xs / xe - 1)))
