"""The distance model's random errors drawn in one compiled pass (for Monte Carlo of whole networks).

:func:`multilat.budget.sample_distance_errors` draws each of the model's 17 inputs (telemetric: clock,
crosstalk phase, power, phase noise; head: a, c, alpha, gamma, Toh, elevation; target: a', b', c',
Tot, elevation, two misalignment uniforms) as a numpy array over all trials and distances, then
evaluates :func:`multilat.budget.group_errors` array by array: about forty temporary arrays of
``trials x distances``. This module evaluates the same model, input by input and formula by formula,
in one numba loop that draws a distance's inputs, computes its error and writes one number.

Randomness: every trial has its own stream, xoshiro256++ (Blackman & Vigna, "Scrambled linear
pseudorandom number generators", ACM TOMS 47, 2021) seeded by SplitMix64 from one 63-bit seed and
the trial's number; normals by Marsaglia's polar method. The seed is taken from the caller's
:class:`numpy.random.Generator`; called once per Monte Carlo block with the engine's block generator
(:func:`multilat.montecarlo.block_generator`), the numbers depend on the block only, never on chunk
sizes, processes, Dask workers or the threads that share the trials of a block (``prange``). They
are *not* the numbers of :func:`~multilat.budget.sample_distance_errors` (another generator); tests
check that the two agree in distribution (moments, quantiles) within Monte Carlo error.

The air group is not included (as in :func:`~multilat.budget.sample_distance_errors`).
Without numba the same loop runs as plain Python (slow; for tests of the formulas only).

IEEE division (``multilat._numba.njit``: ``error_model="numpy"``): a zero divisor gives inf or nan, never an
exception out of a parallel region.
"""

from __future__ import annotations

import math

import numpy as np

from multilat.distributions import Constant, Normal, Uniform
from multilat.errors import MultilatError

from multilat._numba import njit, prange

__all__ = ["INPUTS", "ErrorModel", "error_model", "draw_errors", "errors_of_inputs"]

#: the inputs in the order the kernel reads them (names of :func:`multilat.budget.group_inputs`)
INPUTS = ("clock", "xt_phase", "power_db", "phase_noise", "a", "c", "alpha", "gamma", "toh", "head_el",
          "ta", "tb", "tc", "tot", "target_el", "mis1", "mis2")
_TRANSIT = {"model": 0, "line_of_sight": 1, "target_axis": 2}


class ErrorModel:
    """Per-head input distributions and constants as arrays the kernel reads.

    kind (h, 17) int: 0 normal (p0 mean, p1 std), 1 uniform (p0 low, p1 high), 2 constant (p0)
    const (h, 9): ambiguity_m, crosstalk r = 10^(-SCR/20), am_pm_m_per_db, toh_est_m, tot_est_m,
    b_const_m, half_angle_rad, cone (0/1), cos(half_angle); transit (h,) int: the target transit correction.
    """

    def __init__(self, kind, p0, p1, const, transit):
        self.kind, self.p0, self.p1, self.const, self.transit = kind, p0, p1, const, transit


def error_model(inst, heads) -> ErrorModel:
    """The kernel's arrays for an instrument and a sequence of head names (one row per head)."""
    from multilat import budget

    inst = budget._resolve_inst(inst)
    h = len(heads)
    kind = np.zeros((h, len(INPUTS)), np.int64)
    p0 = np.zeros((h, len(INPUTS)))
    p1 = np.zeros((h, len(INPUTS)))
    const = np.zeros((h, 9))
    transit = np.zeros(h, np.int64)
    for i, name in enumerate(heads):
        dists = budget.group_inputs(inst, name)
        for k, nm in enumerate(INPUTS):
            d = dists[nm]
            if isinstance(d, Normal):
                kind[i, k], p0[i, k], p1[i, k] = 0, d.mean, d.std
            elif isinstance(d, Uniform):
                kind[i, k], p0[i, k], p1[i, k] = 1, d.low, d.high
            elif isinstance(d, Constant):
                kind[i, k], p0[i, k] = 2, d.value
            else:  # pragma: no cover - group_inputs builds only these three
                raise MultilatError(f"input {nm!r} of head {name!r}: {type(d).__name__} is not supported")
        p = budget._params(inst, name)
        if p.cone and not p.half_angle_rad < math.pi / 2:
            raise MultilatError(f"head {name!r}: a cone misalignment needs a half-angle below 90 deg")
        if p.transit_correction not in _TRANSIT:  # pragma: no cover - validated by the instrument model
            raise MultilatError(f"unknown transit correction {p.transit_correction!r}")
        const[i] = (p.ambiguity_m, 10.0 ** (-p.scr_db / 20.0), p.am_pm_m_per_db, p.toh_est_m, p.tot_est_m,
                    p.b_const_m, p.half_angle_rad, 1.0 if p.cone else 0.0, math.cos(p.half_angle_rad))
        transit[i] = _TRANSIT[p.transit_correction]
    return ErrorModel(kind, p0, p1, const, transit)


@njit(cache=True, inline="always")
def _rotl(x, k):
    return (x << np.uint64(k)) | (x >> np.uint64(64 - k))


@njit(cache=True, inline="always")
def _splitmix64(x):
    """One step of SplitMix64 (Steele, Lea & Flood 2014): returns (new state, output)."""
    x = x + np.uint64(0x9E3779B97F4A7C15)
    z = x
    z = (z ^ (z >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
    z = (z ^ (z >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
    return x, z ^ (z >> np.uint64(31))


@njit(cache=True, inline="always")
def _uniform(s):
    """xoshiro256++ (Blackman & Vigna 2021) step on the state ``s`` (4,) uint64; a double in [0, 1)."""
    result = _rotl(s[0] + s[3], 23) + s[0]
    t = s[1] << np.uint64(17)
    s[2] ^= s[0]
    s[3] ^= s[1]
    s[1] ^= s[2]
    s[0] ^= s[3]
    s[2] ^= t
    s[3] = _rotl(s[3], 45)
    return float(result >> np.uint64(11)) * (1.0 / 9007199254740992.0)


@njit(cache=True, inline="always")
def _normal_pair(s):
    """Two independent standard normals by Marsaglia's polar method."""
    while True:
        u = 2.0 * _uniform(s) - 1.0
        v = 2.0 * _uniform(s) - 1.0
        q = u * u + v * v
        if 0.0 < q < 1.0:
            f = math.sqrt(-2.0 * math.log(q) / q)
            return u * f, v * f


@njit(cache=True, inline="always")
def _one_error(L, x, c9, transit):
    """Error (m) of one distance ``L`` for the 17 inputs ``x`` (order :data:`INPUTS`); ``c9`` a row of
    ``ErrorModel.const``. The formulas of :func:`multilat.budget.group_errors`, telemetric + head + target."""
    two_pi = 2.0 * math.pi
    clock, psi, power, pn = x[0], x[1], x[2], x[3]
    a, c, al, ga, toh, hel = x[4], x[5], x[6], x[7], x[8], x[9]
    ta, tb, tc, tot, tel, mis1, mis2 = x[10], x[11], x[12], x[13], x[14], x[15], x[16]
    amb, r, ampm, toh_est, tot_est, b_const, half, cone, cos_half = (c9[0], c9[1], c9[2], c9[3], c9[4],
                                                                     c9[5], c9[6], c9[7], c9[8])
    # telemetric (budget.group_errors; adm.crosstalk_phase_error_rad)
    tele = (-clock * L + math.atan2(r * math.sin(psi), 1.0 + r * math.cos(psi)) / two_pi * amb
            + ampm * power + pn / two_pi * amb)
    # head: eq. (4) forward (gimbal.head_measured_distance), eq. (2) inverse with the estimate
    sal, cal, sga, cga, she, che = (math.sin(al), math.cos(al), math.sin(ga), math.cos(ga),
                                    math.sin(hel), math.cos(hel))
    s = a * sal + math.sqrt(L * L - (a * cal) ** 2)
    ri = c * sga + math.sqrt(s * s - (c * cga) ** 2)
    cos_el_ga = che * cga + she * sga                       # cos(hel - ga)
    rm = math.sqrt(toh * toh + ri * ri + 2.0 * toh * ri * cal * cos_el_ga)
    head = -toh_est * che + math.sqrt(rm * rm - (toh_est * she) ** 2) - L
    # target misalignment (budget._misalignment), as sines and cosines of theta'', phi''
    ce, se = math.cos(tel), math.sin(tel)
    if cone > 0.5:
        # phi'' = asin(sin_r sin psi) in [-pi/2, pi/2] (cos >= 0); theta'' = atan2(sin_r cos psi,
        # cos_r) with cos_r > 0 (half-angle < 90 deg): its sine and cosine without the angles
        cos_r = 1.0 - mis1 * (1.0 - cos_half)
        sin_r = math.sqrt(max(0.0, 1.0 - cos_r * cos_r))
        pp = two_pi * mis2
        sp = sin_r * math.sin(pp)
        cp = math.sqrt(max(0.0, 1.0 - sp * sp))
        y = sin_r * math.cos(pp)
        hyp = math.sqrt(cos_r * cos_r + y * y)
        ct, st = cos_r / hyp, y / hyp
    else:
        th = half * (2.0 * mis1 - 1.0)
        ph = half * (2.0 * mis2 - 1.0)
        ct, st, cp, sp = math.cos(th), math.sin(th), math.cos(ph), math.sin(ph)
    # target: eq. (5) (gimbal.target_measured_distance)
    rm2 = (L * L + tot * tot + ta * ta + tb * tb + tc * tc + 2.0 * ta * L * st
           + 2.0 * tb * (tot * ce - L * ct * cp) + 2.0 * tc * (L * sp - tot * se)
           - 2.0 * tot * L * (ce * ct * cp + se * sp))
    rmt = math.sqrt(rm2)
    # transit correction (gimbal.target_transit_offset_correction)
    if transit == 0:
        kk = ce * ct * cp + se * sp
    elif transit == 1:
        sin_eps = min(1.0, max(-1.0, ct * cp * se - sp * ce))
        kk = math.sqrt(1.0 - sin_eps * sin_eps)               # cos(asin(.)), >= 0
    else:
        kk = ce
    target = tot_est * kk + math.sqrt(rmt * rmt - tot_est * tot_est * (1.0 - kk * kk)) - L + b_const
    return tele + head + target


@njit(cache=True, parallel=True, nogil=True)
def _kernel(seed, first_row, n, distance_m, head_row, kind, p0, p1, const, transit, out):
    m = distance_m.shape[0]
    for t in prange(n):
        # the trial's own stream: xoshiro256++ seeded by SplitMix64 from (seed, trial number)
        rs = np.empty(4, np.uint64)
        z = np.uint64(seed) ^ (np.uint64(first_row + t) * np.uint64(0xD1B54A32D192ED03))
        for k in range(4):
            z, rs[k] = _splitmix64(z)
        x = np.empty(17)
        spare = 0.0
        have_spare = False
        for j in range(m):
            i = head_row[j]
            L = distance_m[j]
            for k in range(17):
                kd = kind[i, k]
                if kd == 0:
                    if have_spare:
                        g = spare
                        have_spare = False
                    else:
                        g, spare = _normal_pair(rs)
                        have_spare = True
                    x[k] = p0[i, k] + p1[i, k] * g
                elif kd == 1:
                    x[k] = p0[i, k] + (p1[i, k] - p0[i, k]) * _uniform(rs)
                else:
                    x[k] = p0[i, k]
            out[t, j] = _one_error(L, x, const[i], transit[i])


@njit(cache=True)
def _errors_of_inputs(distance_m, inputs, c9, transit):
    out = np.empty(distance_m.shape[0])
    for k in range(distance_m.shape[0]):
        out[k] = _one_error(distance_m[k], inputs[k], c9, transit)
    return out


def errors_of_inputs(model: ErrorModel, row: int, distance_m, inputs) -> np.ndarray:
    """The kernel's formulas for given inputs (n, 17) (order :data:`INPUTS`) at distances (n,): the
    error (m) of each; for checking the compiled model against :func:`multilat.budget.group_errors`."""
    return _errors_of_inputs(np.ascontiguousarray(distance_m, float), np.ascontiguousarray(inputs, float),
                             model.const[row], int(model.transit[row]))


def draw_errors(model: ErrorModel, head_row, distance_m, trials: int, rng: np.random.Generator) -> np.ndarray:
    """Errors (measured - true, m) of ``trials`` draws of every distance, shape (trials, m).

    Parameters
    ----------
    model : ErrorModel from :func:`error_model`
    head_row : ndarray of int (m,)  the row of ``model`` (head) of each distance
    distance_m : ndarray (m,)  true distances (> 0)
    trials : int
    rng : numpy Generator; one 32-bit seed is taken from it
    """
    d = np.ascontiguousarray(distance_m, dtype=float)
    if not (np.all(np.isfinite(d)) and np.all(d > 0)):
        raise MultilatError("distance_m must be finite and > 0")
    rows = np.ascontiguousarray(head_row, dtype=np.int64)
    out = np.empty((int(trials), d.size))
    seed = int(rng.integers(0, 2**63 - 1))
    _kernel(seed, 0, int(trials), d, rows, model.kind, model.p0, model.p1, model.const, model.transit, out)
    return out
