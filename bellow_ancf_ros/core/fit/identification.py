"""Parameter identification of the equivalent actuator (paper section V).

Three experiments identify the three equivalent mechanical parameters of a
bellow-shaped actuator (paper Fig. 2(a)); numpy/scipy only, no ROS.

1. Structural stiffness ``k(lam)`` (V.A) from a tensile/compression test,
   :func:`fit_stiffness`.
2. Effective actuation diameter ``D_eff`` (V.B) from actuation force vs
   pressure, :func:`fit_deff`.
3. Cross-sectional diameter ``D_a`` (V.C) from the tip drop of a horizontally
   clamped, unactuated actuator, :func:`identify_da`.

Structural stiffness: from ``F(dl)`` to ``k(lam)`` and ``l0``
-------------------------------------------------------------
The test measures the elastic force of one actuator against its length change
``dl``.  Eq. (1) defines ``k`` by ``F = k(lam) * dl`` with ``dl = (lam - 1) l0``.
A polynomial without constant term (``F(0) = 0``: no force without
elongation) is fitted::

    F(dl) = a1*dl + a2*dl**2 + ... + aN*dl**N

and since ``k(lam) = F(dl)/dl``::

    k(lam) = a1 + a2*dl + ... + aN*dl**(N-1),    dl = l0*(lam - 1)

which is expanded into ascending powers of ``lam`` (the robot file's
``stiffness_coeffs_n_per_m``).  For the paper's quadratic,
``F = 5990.4 dl^2 + 605.9 dl``::

    k(lam) = a2*l0*lam + (a1 - a2*l0)

The force curve alone does not fix ``l0`` (it is the measured unpressurised
length of the actuator, an input here).  Conversely, the paper's two fits
together imply it: the slope of ``k`` is ``a2*l0 = 576.94`` N/m, so
``l0 = 576.94/5990.4 = 0.09631`` m (:func:`l0_from_paper_fits`; docs/model.md
section 5 uses 0.0963 m).  The paper's constant, 28.9 N/m, is
``a1 - a2*l0 = 605.9 - 576.94 = 28.96`` N/m written with one decimal
truncated; the shipped robot keeps the paper's 28.9.

Gravity share (paper V.A): with the whole segment in the testing machine the
machine force ``F_m`` is shared by the ``n_a`` actuators and includes the
weight the machine carries, so each actuator's elastic force is
``F_e = F_m/n_a - F_g``.  ``F_g`` is the gravity share per actuator; the
default (:func:`default_gravity_share`) is the top plate's weight divided by
``n_a`` (the machine holds the top plate of an upright segment).  With
``force_per='actuator'`` the data are one actuator's force and only ``F_g``
(default 0) is subtracted.

Fit quality: ``R^2 = 1 - SS_res/SS_tot`` (``SS_tot`` about the mean) and the
RMS of the residuals, both of ``F_e``.

Effective actuation diameter
----------------------------
The actuation force is ``F_a = pi/4 * D_eff**2 * P`` (eq. 10), so the slope
of ``F_a`` against ``P`` is the effective area ``A_eff`` and
``D_eff = sqrt(4*A_eff/pi)``.  An ordinary least-squares line (with
intercept, which absorbs a force offset such as an untared load cell) gives
the slope and its standard error; the two-sided confidence interval of the
slope (Student t, ``n - 2`` degrees of freedom) maps monotonically onto one of
``D_eff``.  The data may hold the actuation force directly, or the measured
actuator length, from which ``F_a = k(lam)*(lam - 1)*l0 - F_g`` (paper V.B,
``lam = l/l0``; ``F_g`` the gravity load that stretches the hanging actuator).

Cross-sectional diameter
------------------------
The rig of paper V.C: one actuator clamped horizontally at ``lam = 1`` (base
point fixed, base gradient parallel to the clamp axis, its length free, as at
every plate), loaded by its own weight (linear density ``rho0`` of the robot
file) and an end mass, discretised with 20 elements
(:class:`~bellow_ancf_ros.core.fit._cantilever.Cantilever`), ``k_t = k(1)*l0``
(eq. 2), ``k_b = D_a**2*l0*k(1)/8`` (eq. 4, ``lam = 1``).  The tip drop
decreases strictly with ``D_a``; the paper's optimisation (31) is therefore a
root-finding problem ``drop(D_a) = measured``, solved by a bracketing root
finder (:func:`scipy.optimize.brentq`; the paper used bisection).  The paper
does not state its end mass: with the shipped robot (``rho0 = 0.20`` kg/m,
assumed) an end mass of 23.97 g makes the paper's 34.35 mm drop give the
paper's 17.90 mm (:func:`tip_mass_for_da`, :data:`PAPER_END_MASS_KG`).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field
from typing import Any, Sequence

import numpy as np
from numpy.polynomial import polynomial as npoly
from scipy import optimize

from ._cantilever import Cantilever
from ..model import RobotConfig

__all__ = [
    'PAPER_F_COEFFS', 'PAPER_K_COEFFS', 'PAPER_L0', 'PAPER_D_EFF', 'PAPER_D_A', 'PAPER_DROP',
    'PAPER_END_MASS_KG', 'GRAVITY',
    'StiffnessFit', 'DeffFit', 'DaResult',
    'stiffness_from_force_poly', 'force_poly_from_stiffness', 'l0_from_paper_fits',
    'default_gravity_share', 'fit_stiffness', 'fit_deff', 'actuation_force_from_length',
    'cantilever_tip_drop', 'identify_da', 'tip_mass_for_da', 'read_table', 'poly_text',
]

GRAVITY = 9.81
#: paper V.A: F_e = 5990.4 dl^2 + 605.9 dl (ascending: a1, a2) [N/m, N/m^2]
PAPER_F_COEFFS = (605.9, 5990.4)
#: paper V.A: k(lam) = 576.94 lam + 28.9 (ascending) [N/m]
PAPER_K_COEFFS = (28.9, 576.94)
#: l0 implied by the two fits (docs/model.md section 5) [m]
PAPER_L0 = 0.0963
#: paper V.B [m]
PAPER_D_EFF = 8.087e-3
#: paper V.C [m]
PAPER_D_A = 17.90e-3
#: paper V.C: measured tip drop [m]
PAPER_DROP = 34.35e-3
#: end mass [kg] with which the shipped one-segment robot (rho0 = 0.20 kg/m)
#: maps the paper's 34.35 mm drop onto its 17.90 mm (the paper does not state
#: it; :func:`tip_mass_for_da` computes it: 0.0239723 kg)
PAPER_END_MASS_KG = 0.02397


# ------------------------------------------------------------- data files
def read_table(path: str) -> dict[str, np.ndarray]:
    """Read a CSV data file: ``#`` comment lines, one header row, numeric rows.

    Returns ``{column name (lower case, stripped): float array}``.  Blank
    lines are skipped.  Raises ``ValueError`` naming the line of a bad row
    (``OSError`` if the file cannot be read).
    """
    import csv

    header = None
    rows: list[list[float]] = []
    with open(path, newline='', encoding='utf-8-sig') as fh:
        for line_no, row in enumerate(csv.reader(fh), start=1):
            cells = [c.strip() for c in row]
            if not any(cells) or cells[0].startswith('#'):
                continue
            if header is None:
                header = [c.lower() for c in cells]
                if len(set(header)) != len(header):
                    raise ValueError(f'line {line_no}: duplicated column names in the header')
                try:
                    [float(c) for c in cells]
                except ValueError:
                    continue
                raise ValueError(f'line {line_no}: expected a header row of column names, '
                                 'got numbers')
            if len(cells) != len(header):
                raise ValueError(f'line {line_no}: expected {len(header)} fields, '
                                 f'got {len(cells)}')
            try:
                values = [float(c) for c in cells]
            except ValueError:
                raise ValueError(f'line {line_no}: not a number in {row!r}') from None
            if not all(math.isfinite(v) for v in values):
                raise ValueError(f'line {line_no}: not a finite number in {row!r}')
            rows.append(values)
    if header is None:
        raise ValueError('no header row (the file holds no data)')
    if not rows:
        raise ValueError('no data rows after the header')
    data = np.array(rows, dtype=float)
    return {name: data[:, i] for i, name in enumerate(header)}


# ------------------------------------------------------------ polynomials
def stiffness_from_force_poly(f_coeffs: Sequence[float], l0: float) -> np.ndarray:
    """``k(lam)`` coefficients (ascending in ``lam``) from ``F(dl) = sum a_j dl^j``.

    ``f_coeffs = (a1, a2, ..., aN)`` (no constant term).  ``k(lam) = F(dl)/dl
    = sum_j a_j (l0 (lam - 1))^(j-1)`` expanded in powers of ``lam``.
    """
    a = np.asarray(f_coeffs, dtype=float).ravel()
    if a.size == 0:
        raise ValueError('the force polynomial needs at least the linear coefficient')
    if not (math.isfinite(l0) and l0 > 0):
        raise ValueError(f'l0 must be a positive length, got {l0!r}')
    k = np.zeros(a.size)
    base = np.array([-l0, l0])                      # dl = l0*lam - l0, ascending in lam
    power = np.array([1.0])
    for aj in a:                                    # aj multiplies dl**(j-1)
        k[: power.size] += aj * power
        power = npoly.polymul(power, base)
    return k


def force_poly_from_stiffness(k_coeffs: Sequence[float], l0: float) -> np.ndarray:
    """Inverse of :func:`stiffness_from_force_poly`: ``(a1, ..., aN)`` of ``F(dl) = k(lam) dl``."""
    k = np.asarray(k_coeffs, dtype=float).ravel()
    # k(lam) with lam = 1 + dl/l0, ascending in dl
    out = np.zeros(k.size)
    base = np.array([1.0, 1.0 / l0])
    power = np.array([1.0])
    for c in k:
        out[: power.size] += c * power
        power = npoly.polymul(power, base)
    return out                                      # coefficient of dl^(j-1) = a_j


def l0_from_paper_fits(k_slope: float = PAPER_K_COEFFS[1], a2: float = PAPER_F_COEFFS[1]) -> float:
    """``l0`` implied by a quadratic force fit and the slope of ``k``.

    That is ``k1/a2`` (576.94/5990.4).
    """
    return float(k_slope) / float(a2)


def default_gravity_share(cfg: RobotConfig | None, force_per: str = 'segment',
                          g: float = GRAVITY) -> float:
    """Gravity share ``F_g`` per actuator [N] subtracted from a tensile test (paper V.A).

    ``segment``: the weight of the first segment's top plate shared by its
    ``n_a`` actuators; ``actuator``: 0.
    """
    if force_per == 'actuator' or cfg is None:
        return 0.0
    seg = cfg.segments[0]
    return g * seg.top_plate_mass / seg.n_actuators


# -------------------------------------------------------- stiffness fit
@dataclass
class StiffnessFit:
    """Result of :func:`fit_stiffness` (SI units)."""

    order: int
    f_coeffs: list            # a1..aN of F(dl) [N/m^j], ascending
    k_coeffs: list            # k(lam) ascending in lam [N/m]
    l0: float
    r2: float
    rms_n: float
    max_abs_residual_n: float
    n_points: int
    force_per: str
    n_actuators: int
    gravity_share_n: float
    dl_range_m: tuple
    f_coeffs_stderr: list = field(default_factory=list)
    k_coeffs_stderr: list = field(default_factory=list)
    dl: np.ndarray = field(default=None, repr=False)
    force_elastic: np.ndarray = field(default=None, repr=False)

    def force(self, dl):
        """Fitted ``F(dl)`` [N]."""
        dl = np.asarray(dl, dtype=float)
        return dl * npoly.polyval(dl, self.f_coeffs)

    def k(self, lam):
        return npoly.polyval(np.asarray(lam, dtype=float), self.k_coeffs)

    def to_dict(self) -> dict[str, Any]:
        d = asdict(self)
        d.pop('dl'), d.pop('force_elastic')
        d['dl_range_m'] = list(self.dl_range_m)
        d['k_text'] = poly_text(self.k_coeffs, 'lam')
        d['f_text'] = poly_text([0.0] + list(self.f_coeffs), 'dl')
        return d


def poly_text(coeffs: Sequence[float], var: str) -> str:
    """``'576.94*lam + 28.9'`` style text, highest power first, zero terms dropped."""
    terms = []
    for p in range(len(coeffs) - 1, -1, -1):
        c = float(coeffs[p])
        if c == 0.0 and len(coeffs) > 1:
            continue
        mono = '' if p == 0 else (var if p == 1 else f'{var}^{p}')
        body = f'{abs(c):.6g}' + (f'*{mono}' if mono else '')
        terms.append((c < 0, body))
    if not terms:
        return '0'
    out = ('-' if terms[0][0] else '') + terms[0][1]
    for neg, body in terms[1:]:
        out += (' - ' if neg else ' + ') + body
    return out


def _paired_data(x, y, x_name: str, y_name: str):
    """Two measured columns as flat float arrays of equal length, all finite (else ValueError)."""
    x = np.asarray(x, dtype=float).ravel()
    y = np.asarray(y, dtype=float).ravel()
    if x.shape != y.shape:
        raise ValueError(f'{x_name} and {y_name} must have the same length')
    if not (np.all(np.isfinite(x)) and np.all(np.isfinite(y))):
        raise ValueError('the data must be finite numbers')
    return x, y


def _r2_rms(y, yhat):
    res = y - yhat
    ss_res = float(np.sum(res ** 2))
    ss_tot = float(np.sum((y - np.mean(y)) ** 2))
    r2 = 1.0 - ss_res / ss_tot if ss_tot > 0 else float('nan')
    return r2, float(np.sqrt(np.mean(res ** 2))), float(np.max(np.abs(res)))


def fit_stiffness(dl, force, order: int = 2, l0: float = PAPER_L0, force_per: str = 'segment',
                  n_actuators: int = 3, gravity_share_n: float = 0.0) -> StiffnessFit:
    """Fit ``F_e(dl)`` (no constant term) of the given order; derive ``k(lam)``.

    Parameters
    ----------
    dl : length changes [m] (negative in compression).
    force : measured force [N]: of the whole segment (``force_per='segment'``,
        the machine force ``F_m``) or of one actuator.
    order : polynomial order ``N >= 1`` of ``F(dl)``.
    l0 : unpressurised actuator length [m].
    n_actuators : actuators sharing the machine force (segment mode).
    gravity_share_n : ``F_g`` per actuator [N], subtracted: ``F_e = F_m/n_a - F_g``.
    """
    dl, force = _paired_data(dl, force, 'dl', 'force')
    order = int(order)
    if order < 1:
        raise ValueError(f'the polynomial order must be >= 1, got {order}')
    if force_per not in ('segment', 'actuator'):
        raise ValueError(f"force_per must be 'segment' or 'actuator', got {force_per!r}")
    if force_per == 'segment' and n_actuators < 1:
        raise ValueError('n_actuators must be >= 1')
    distinct = np.unique(dl[dl != 0.0]).size
    if distinct < order or dl.size < order + 1:
        raise ValueError(f'a polynomial of order {order} needs at least {order + 1} data points '
                         f'with {order} distinct non-zero dl, got {dl.size} points')
    fe = (force / n_actuators if force_per == 'segment' else force) - gravity_share_n
    scale = float(np.max(np.abs(dl)))
    V = np.stack([(dl / scale) ** j for j in range(1, order + 1)], axis=1)
    c, *_ = np.linalg.lstsq(V, fe, rcond=None)
    f_coeffs = c / scale ** np.arange(1, order + 1)
    yhat = V @ c
    r2, rms, mx = _r2_rms(fe, yhat)
    dof = dl.size - order
    stderr = [float('nan')] * order
    k_stderr = [float('nan')] * order
    k = stiffness_from_force_poly(f_coeffs, l0)
    if dof > 0:
        s2 = float(np.sum((fe - yhat) ** 2)) / dof
        try:
            unscale = np.diag(1.0 / scale ** np.arange(1, order + 1))
            cov = unscale @ (s2 * np.linalg.inv(V.T @ V)) @ unscale
            stderr = list(np.sqrt(np.maximum(np.diag(cov), 0.0)))
            # k = M a is linear in the force coefficients: cov_k = M cov M^T
            M = np.stack([stiffness_from_force_poly(e, l0) for e in np.eye(order)], axis=1)
            k_stderr = list(np.sqrt(np.maximum(np.diag(M @ cov @ M.T), 0.0)))
        except np.linalg.LinAlgError:
            pass
    return StiffnessFit(
        order=order, f_coeffs=[float(v) for v in f_coeffs], k_coeffs=[float(v) for v in k],
        l0=float(l0), r2=r2, rms_n=rms, max_abs_residual_n=mx, n_points=int(dl.size),
        force_per=force_per, n_actuators=int(n_actuators), gravity_share_n=float(gravity_share_n),
        dl_range_m=(float(dl.min()), float(dl.max())), f_coeffs_stderr=[float(s) for s in stderr],
        k_coeffs_stderr=[float(s) for s in k_stderr],
        dl=dl, force_elastic=fe,
    )


# ------------------------------------------------------------ D_eff fit
@dataclass
class DeffFit:
    """Result of :func:`fit_deff` (SI units)."""

    d_eff_m: float
    d_eff_ci_m: tuple
    confidence: float
    area_m2: float
    area_stderr_m2: float
    intercept_n: float
    r2: float
    rms_n: float
    n_points: int
    pressure_range_pa: tuple
    pressure: np.ndarray = field(default=None, repr=False)
    force: np.ndarray = field(default=None, repr=False)

    def to_dict(self) -> dict[str, Any]:
        d = asdict(self)
        d.pop('pressure'), d.pop('force')
        d['d_eff_ci_m'] = list(self.d_eff_ci_m)
        d['pressure_range_pa'] = list(self.pressure_range_pa)
        return d


def actuation_force_from_length(length_m, k_coeffs, l0, gravity_share_n=0.0):
    """Actuation force from a measured actuator length: ``k(lam)(lam-1) l0 - F_g`` (paper V.B)."""
    lam = np.asarray(length_m, dtype=float) / l0
    k = npoly.polyval(lam, np.asarray(k_coeffs, dtype=float))
    return k * (lam - 1.0) * l0 - gravity_share_n


def fit_deff(pressure_pa, force_n, confidence: float = 0.95) -> DeffFit:
    """``D_eff`` from the slope of actuation force vs pressure (eq. 10: ``F = pi/4 D^2 P``).

    Ordinary least squares with intercept (:func:`scipy.stats.linregress`);
    the confidence interval of ``D_eff`` is the image of the slope's Student-t
    interval (``n - 2`` degrees of freedom).
    """
    p, f = _paired_data(pressure_pa, force_n, 'pressure', 'force')
    if p.size < 3 or np.unique(p).size < 2:
        raise ValueError(f'need at least 3 points at 2 or more distinct pressures, got {p.size}')
    if not 0.0 < confidence < 1.0:
        raise ValueError(f'confidence must lie in (0, 1), got {confidence}')
    from scipy import stats   # (here: importing it costs a node process some 0.9 s at start)
    lr = stats.linregress(p, f)
    slope, se = float(lr.slope), float(lr.stderr)
    if not slope > 0:
        raise ValueError('the force does not increase with the pressure '
                         f'(slope {slope:.3g} N/Pa): check the columns and their signs')
    tq = float(stats.t.ppf(0.5 + confidence / 2.0, p.size - 2))
    lo, hi = slope - tq * se, slope + tq * se

    def diam(area):
        return math.sqrt(4.0 * area / math.pi) if area > 0 else 0.0

    yhat = lr.intercept + slope * p
    r2, rms, _ = _r2_rms(f, yhat)
    return DeffFit(
        d_eff_m=diam(slope), d_eff_ci_m=(diam(lo), diam(hi)), confidence=float(confidence),
        area_m2=slope, area_stderr_m2=se, intercept_n=float(lr.intercept), r2=r2, rms_n=rms,
        n_points=int(p.size), pressure_range_pa=(float(p.min()), float(p.max())),
        pressure=p, force=f,
    )


# ---------------------------------------------------------- D_a (V.C)
def _k1(cfg: RobotConfig) -> float:
    return float(npoly.polyval(1.0, np.asarray(cfg.stiffness_coeffs, dtype=float)))


def cantilever_tip_drop(cfg: RobotConfig, d_a: float, tip_mass_kg: float, n: int = 20,
                        g: float = GRAVITY) -> float:
    """Tip drop [m] of the clamped unactuated actuator (lam = 1) of ``cfg`` for a given ``D_a``.

    ``k_t = k(1) l0`` (eq. 2), ``k_b = D_a^2 l0 k(1)/8`` (eq. 4), linear
    density ``rho0``; raises ``RuntimeError`` if the equilibrium is not found.
    """
    k1 = _k1(cfg)
    kb = d_a ** 2 * cfg.l0 * k1 / 8.0
    res = Cantilever(cfg.l0, k1 * cfg.l0, kb, cfg.rho0, tip_mass_kg, n=n, g=g).solve()
    if not res.converged:
        raise RuntimeError(f'cantilever equilibrium not found for D_a = {d_a * 1e3:.4g} mm: '
                           f'{res.message}')
    return res.tip_drop


@dataclass
class DaResult:
    """Result of :func:`identify_da` (SI units)."""

    D_a_m: float
    drop_m: float
    model_drop_m: float
    tip_mass_kg: float
    n_elements: int
    xtol_m: float
    rtol: float
    iterations: int
    function_calls: int
    bracket_m: tuple
    converged: bool
    k1_n_per_m: float
    kt_n: float
    kb_n_m2: float
    rho0_kg_per_m: float
    l0_m: float

    def to_dict(self) -> dict[str, Any]:
        d = asdict(self)
        d['bracket_m'] = list(self.bracket_m)
        return d


def identify_da(cfg: RobotConfig, drop_m: float, tip_mass_kg: float, n: int = 20,
                xtol: float = 1e-8, rtol: float = 1e-10, g: float = GRAVITY,
                guess: float | None = None) -> DaResult:
    """``D_a`` such that the model's tip drop equals the measured ``drop_m`` (paper eq. 31).

    The drop decreases strictly with ``D_a``.  A bracket is grown
    geometrically from ``guess`` (default: the robot file's ``D_a``) until
    the sign changes, then :func:`scipy.optimize.brentq` finds the root to
    ``xtol`` [m] / ``rtol``.

    Raises ``ValueError`` if the drop cannot be matched: not positive, not
    below ``0.9 l0``, or no bracket found.
    """
    drop_m = float(drop_m)
    tip_mass_kg = float(tip_mass_kg)
    if not (math.isfinite(drop_m) and drop_m > 0):
        raise ValueError(f'the measured drop must be a positive length, got {drop_m!r} m')
    if not (math.isfinite(tip_mass_kg) and tip_mass_kg >= 0):
        raise ValueError(f'the tip mass must be a non-negative mass, got {tip_mass_kg!r} kg')
    if drop_m >= 0.9 * cfg.l0:
        raise ValueError(f'a drop of {drop_m * 1e3:.4g} mm is not below 90 % of the actuator '
                         f'length ({cfg.l0 * 1e3:.4g} mm): no beam model can identify D_a from it')
    calls = [0]

    def f(d):
        calls[0] += 1
        return cantilever_tip_drop(cfg, d, tip_mass_kg, n=n, g=g) - drop_m

    d0 = float(guess if guess is not None else cfg.d_a)
    lo = hi = d0
    flo = fhi = f(d0)
    grow = 1.5
    for _ in range(60):
        if flo > 0 and fhi < 0:
            break
        if fhi >= 0:            # still too soft at hi: stiffen
            lo, flo = hi, fhi
            hi *= grow
            fhi = f(hi)
        if flo <= 0:            # too stiff at lo: soften
            hi, fhi = lo, flo
            lo /= grow
            try:
                flo = f(lo)
            except RuntimeError:
                raise ValueError(f'a drop of {drop_m * 1e3:.4g} mm needs so soft an actuator that '
                                 'its equilibrium cannot be found') from None
        if flo == 0.0 or fhi == 0.0:
            break
    else:
        raise ValueError(f'no D_a gives a drop of {drop_m * 1e3:.4g} mm with a '
                         f'{tip_mass_kg:g} kg end mass')
    if flo == 0.0:
        root, it, conv = lo, 0, True
    elif fhi == 0.0:
        root, it, conv = hi, 0, True
    else:
        root, info = optimize.brentq(f, lo, hi, xtol=xtol, rtol=rtol, full_output=True)
        it, conv = int(info.iterations), bool(info.converged)
    k1 = _k1(cfg)
    model_drop = cantilever_tip_drop(cfg, root, tip_mass_kg, n=n, g=g)
    return DaResult(
        D_a_m=float(root), drop_m=drop_m, model_drop_m=float(model_drop), tip_mass_kg=tip_mass_kg,
        n_elements=int(n), xtol_m=float(xtol), rtol=float(rtol), iterations=it,
        function_calls=calls[0], bracket_m=(float(lo), float(hi)), converged=conv,
        k1_n_per_m=k1, kt_n=k1 * cfg.l0, kb_n_m2=root ** 2 * cfg.l0 * k1 / 8.0,
        rho0_kg_per_m=float(cfg.rho0), l0_m=float(cfg.l0),
    )


def tip_mass_for_da(cfg: RobotConfig, d_a: float = PAPER_D_A, drop_m: float = PAPER_DROP,
                    n: int = 20, g: float = GRAVITY, xtol: float = 1e-9) -> float:
    """End mass [kg] for which ``D_a`` gives the tip drop ``drop_m``.

    This is the paper's unstated end mass.  The drop increases strictly with
    the end mass; bracketing root finder.
    """
    def f(m):
        return cantilever_tip_drop(cfg, d_a, m, n=n, g=g) - drop_m

    if f(0.0) >= 0:
        raise ValueError('the actuator drops that far under its own weight alone')
    hi = 0.01
    while f(hi) < 0:
        hi *= 2.0
        if hi > 100.0:
            raise ValueError('no end mass reproduces that drop')
    return float(optimize.brentq(f, 0.0, hi, xtol=xtol))
