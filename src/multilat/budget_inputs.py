"""Per-input uncertainty budget of one measured distance (JCGM 100 table, JCGM 101 contributions).

:mod:`multilat.budget` gives the four groups (telemetric, head, target, air). This module lists the
input quantities of :func:`multilat.budget.group_errors` one per row, with

* its distribution and parameters (from the instrument file), estimate and standard uncertainty;
* its **sensitivity coefficient** ``c_i``: the model's partial derivative at the nominal point (every
  input at its expectation), central differences of :func:`multilat.montecarlo.gum_linear`; where it
  depends on the distance (the clock: ``c = -L``) the root mean square over the distances, signed;
* the **first-order contribution** ``contribution_std_lin_m = |c_i| u(x_i)`` (JCGM 100 §5.1);
* the **Monte Carlo one-at-a-time contribution** ``contribution_std_mc_m``: the standard deviation of
  the group's error with only this input varying, the others held at their expectation
  (:func:`multilat.montecarlo.budget`, pooled over the distances as ``sqrt(mean_L var_L)``);
* its **share of the group's mean-square error** (``share_var_m2``): the Shapley effect of the
  input on the within-distance variance (Owen 2014; Song, Nelson & Staum 2016), estimated by
  pick-freeze (the closed index ``Var(E[e | x_S, L])`` from two independent input draws A, B sharing
  ``x_S`` and the distance). Shapley shares add up exactly to the variance, whatever the interactions
  (the head's ``dToh cos(phi)`` is a product: one-at-a-time gives Toh 2.0 µm and the elevation 0, the
  shares 1.35 and 0.43 µm). One extra row per group, ``bias``, holds the mean square of the group's
  mean error over the distances (uncorrected offsets, seed section 3.4), so that **the rows of a group
  add up to its squared standard uncertainty** ``u^2 = var + mean^2``.

Correlated inputs: the target's misalignment direction ``(theta'', phi'')`` is one joint input (uniform
over the acceptance cone: dependent, uncorrelated by symmetry); it is varied, held and shared as a pair;
its GUM contribution combines the two partial derivatives without covariance. All other inputs are
independent. The groups have disjoint inputs, so the combined error's rows are the union of the
groups' rows; only the bias combines as the square of the sum of the groups' means.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np

from multilat.budget import GROUPS, _params, _resolve_inst, group_errors, group_inputs
from multilat.distributions import Constant, Normal, Uniform
from multilat.errors import MultilatError, require_finite
from multilat.instrument import Instrument
from multilat.montecarlo import budget as mc_budget
from multilat.montecarlo import gum_linear, resolve_seed

__all__ = ["QUANTITIES", "InputBudget", "input_budget"]

#: (key, group, symbol, description, inputs of group_inputs, unit of the input)
QUANTITIES = (
    ("clock", "telemetric", "δf/f", "modulation frequency (clock) relative error", ("clock",), "1"),
    ("xt_phase", "telemetric", "ψ_xt", "crosstalk phasor phase (cyclic error, SCR fixed)", ("xt_phase",), "rad"),
    ("power_db", "telemetric", "ΔP", "received-power variation (AM/PM coupling)", ("power_db",), "dB"),
    ("phase_noise", "telemetric", "δΦ", "phase noise", ("phase_noise",), "rad"),
    ("a", "head", "a", "head beam offset a", ("a",), "m"),
    ("c", "head", "c", "head beam offset c", ("c",), "m"),
    ("alpha", "head", "α", "head beam tilt α", ("alpha",), "rad"),
    ("gamma", "head", "γ", "head beam tilt γ", ("gamma",), "rad"),
    ("toh", "head", "Toh", "head transit offset (corrected with its estimate)", ("toh",), "m"),
    ("head_el", "head", "φ", "head elevation", ("head_el",), "rad"),
    ("ta", "target", "a'", "target beam offset a'", ("ta",), "m"),
    ("tb", "target", "b'", "target beam offset b' (nominal calibrated)", ("tb",), "m"),
    ("tc", "target", "c'", "target beam offset c'", ("tc",), "m"),
    ("tot", "target", "Tot", "target transit offset (corrected with its estimate)", ("tot",), "m"),
    ("target_el", "target", "φ'", "target elevation", ("target_el",), "rad"),
    ("misalignment", "target", "(θ'', φ'')", "target misalignment direction (joint)", ("mis1", "mis2"), "rad"),
    ("d_t", "air", "ΔT", "air temperature sensor error", ("d_t",), "°C"),
    ("d_p", "air", "Δp", "air pressure sensor error", ("d_p",), "hPa"),
    ("d_rh", "air", "ΔRH", "air humidity sensor error", ("d_rh",), "%"),
    ("d_co2", "air", "Δx_CO2", "air CO2 sensor error", ("d_co2",), "ppm"),
)
_GCOL = {g: j for j, g in enumerate(GROUPS)}


def _sources(inst: Instrument, head: str) -> dict:
    """The instrument-file keys each input comes from."""
    hk = f"heads.{head}"
    ab = ("head_common.beam_offset_m" if inst.budget.beam_offset_model == "common" else f"{hk}.a_limit_m")
    cb = ("head_common.beam_offset_m" if inst.budget.beam_offset_model == "common" else f"{hk}.c_limit_m")
    return {
        "clock": "adm.clock_ageing_per_year, adm.calibration_interval_years",
        "xt_phase": "adm.signal_to_crosstalk_db", "power_db": "adm.power_variation_db, adm.am_pm_m_per_db",
        "phase_noise": "adm.phase_noise_rad", "a": ab, "c": cb, "alpha": f"{hk}.alpha_deg",
        "gamma": f"{hk}.gamma_deg", "toh": f"{hk}.toh_m, {hk}.toh_std_m", "head_el": "head_common.elevation_deg",
        "ta": "target.a_m, target.offset_std_m", "tb": "target.b_m, target.offset_std_m",
        "tc": "target.c_m, target.offset_std_m", "tot": "target.tot_m, target.tot_std_m",
        "target_el": "target.elevation_deg",
        "misalignment": "target.misalignment_shape, target.misalignment_half_angle_deg",
        "d_t": "environment.u_temperature_c", "d_p": "environment.u_pressure_hpa",
        "d_rh": "environment.u_humidity_pct", "d_co2": "environment.u_co2_ppm",
    }


# ------------------------------------------------------------------ the joint misalignment input
def _to_mis(cone: bool, half_rad: float, theta, phi):
    """Inverse of :func:`multilat.budget._misalignment`: the two unit uniforms of a direction."""
    if cone:
        cos_r = np.cos(theta) * np.cos(phi)
        mis1 = (1.0 - cos_r) / (1.0 - math.cos(half_rad))
        psi = np.mod(np.arctan2(np.sin(phi), np.sin(theta) * np.cos(phi)), 2.0 * math.pi)
        return mis1, psi / (2.0 * math.pi)
    return 0.5 + theta / (2.0 * half_rad), 0.5 + phi / (2.0 * half_rad)


@dataclass(frozen=True)
class _Misalignment:
    """(theta'', phi'') of the target, rad, as a joint input of shape (n, 2); expectation (0, 0)."""

    cone: bool
    half_rad: float

    @property
    def mean(self):
        return np.zeros(2)

    centre = mean

    def sample(self, rng, size):
        from multilat.budget import _misalignment

        p = _SimpleCone(self.cone, self.half_rad)
        th, ph = _misalignment(p, rng.random(size), rng.random(size))
        return np.stack([th, ph], axis=-1)

    def stds(self) -> tuple:
        """Marginal standard deviations of theta'' and phi'' (rad; Gauss-Legendre quadrature, exact to
        ~1e-12 relative, over cos r uniform and the azimuth uniform for the cone)."""
        if not self.cone:
            return (self.half_rad / math.sqrt(3.0),) * 2
        from multilat.budget import _misalignment

        x, w = np.polynomial.legendre.leggauss(96)
        u1, u2 = np.meshgrid(0.5 * (x + 1.0), 0.5 * (x + 1.0), indexing="ij")
        ww = np.outer(w, w) / 4.0
        th, ph = _misalignment(_SimpleCone(True, self.half_rad), u1, u2)
        return float(np.sqrt(np.sum(ww * th**2))), float(np.sqrt(np.sum(ww * ph**2)))


@dataclass(frozen=True)
class _SimpleCone:
    cone: bool
    half_angle_rad: float


# ------------------------------------------------------------------ models
def _nominal(dists: dict, p) -> dict:
    """Every raw input at its expectation; the misalignment at (0, 0)."""
    out = {nm: float(d.mean) for nm, d in dists.items() if nm not in ("mis1", "mis2")}
    out["mis1"], out["mis2"] = _to_mis(p.cone, p.half_angle_rad, 0.0, 0.0)
    return out


def _group_model(p, distance_m, col, fixed, **kw):
    """The error of one group (m) for the group's inputs ``kw`` (misalignment as (n, 2) theta, phi)."""
    x = dict(fixed)
    if "misalignment" in kw:
        m = kw.pop("misalignment")
        x["mis1"], x["mis2"] = _to_mis(p.cone, p.half_angle_rad, m[:, 0], m[:, 1])
    x.update(kw)
    return group_errors(p, distance_m, **x)[:, col]


def _group_inputs_q(dists, p, group) -> dict:
    """The group's inputs for the one-at-a-time budget: quantity key -> distribution."""
    out = {}
    for key, g, _, _, raw, _ in QUANTITIES:
        if g == group:
            out[key] = _Misalignment(p.cone, p.half_angle_rad) if key == "misalignment" else dists[raw[0]]
    return out


def _describe(d) -> dict:
    if isinstance(d, Normal):
        return {"type": "normal", "mean": float(d.mean), "std": float(d.std)}
    if isinstance(d, Uniform):
        return {"type": "uniform", "low": float(d.low), "high": float(d.high)}
    if isinstance(d, Constant):
        return {"type": "constant", "value": float(d.value)}
    if isinstance(d, _Misalignment):
        return {"type": "uniform over the cone's solid angle" if d.cone else "independent uniforms",
                "half_angle_rad": d.half_rad}
    raise MultilatError(f"no description for {type(d).__name__}")  # pragma: no cover


# ------------------------------------------------------------------ Shapley by pick-freeze
def _shapley_weights(d: int) -> np.ndarray:
    return np.array([math.factorial(s) * math.factorial(d - s - 1) / math.factorial(d) for s in range(d)])


def _closed_indices(p, L, col, fixed, factors, A, B, batches):
    """Per batch: v(S) = mean(yA yS) - mean(yA yB) for every subset mask S of the factors (yS: the
    factors in S from A, the others from B; the difference cancels most of the noise of small effects),
    the bias estimate mean(yA) mean(yB) and the batch mean of yA. Arrays (batches, 2^d), (batches,) x 2."""
    d = len(factors)
    n = next(iter(A.values())).shape[0]
    ys = []
    for mask in range(1 << d):
        x = dict(fixed)
        for k, names in enumerate(factors):
            src = A if mask >> k & 1 else B
            x.update({nm: src[nm] for nm in names})
        ys.append(group_errors(p, L, **x)[:, col])
    y = np.stack(ys)                                  # (2^d, n)
    ya = y[-1].reshape(batches, n // batches)
    prod = (y.reshape(1 << d, batches, n // batches) * ya[None]).mean(axis=2).T   # (batches, 2^d)
    # the mean square of the mean: the product of two independent sample means (unbiased, and far less
    # noisy than mean(yA yB) for a group whose mean is zero)
    bias = ya.mean(axis=1) * y[0].reshape(batches, n // batches).mean(axis=1)
    return prod - prod[:, :1], bias, ya.mean(axis=1)


def _shapley(v: np.ndarray, d: int) -> np.ndarray:
    """Shapley values (batches, d) from closed indices v (batches, 2^d), v[:, 0] = 0."""
    w = _shapley_weights(d)
    phi = np.zeros((v.shape[0], d))
    for mask in range(1 << d):
        s = bin(mask).count("1")
        for i in range(d):
            if not mask >> i & 1:
                phi[:, i] += w[s] * (v[:, mask | (1 << i)] - v[:, mask])
    return phi


# ------------------------------------------------------------------ result
@dataclass(frozen=True)
class InputBudget:
    """Per-input budget of one distance (see the module docstring).

    Attributes
    ----------
    rows : list of dict
        One per input quantity (order :data:`QUANTITIES`) and one ``bias`` row per group; keys
        ``quantity, symbol, description, group, unit, source, distribution, estimate, estimate_std``
        (in ``unit``), ``sensitivity`` (m per ``unit``), ``sensitivity_unit``, ``contribution_std_lin_m``
        (``|c| u(x)``), ``contribution_std_mc_m`` (this input alone), ``share_var_m2`` (its share of
        the group's u^2), ``share_var_se_m2`` (Monte Carlo standard error), ``share_std_m``
        (``sign * sqrt(|share|)``).
    groups : dict group -> dict
        ``error_rms_m`` (root of the sum of its rows' shares), ``error_rms_se_m``, ``error_mean_m``,
        ``error_var_m2``, ``error_mean_square_m2`` (the bias row).
    error_rms_m, error_rms_se_m : float
        Root of the sum of the included groups' variance shares plus the square of their summed mean
        (the combined error, as in :class:`multilat.budget.DistanceBudget`).
    include_air : bool
    trials_per_distance, batches : int
    """

    rows: list
    groups: dict
    error_rms_m: float
    error_rms_se_m: float
    include_air: bool
    trials_per_distance: int
    batches: int

    def to_dict(self) -> dict:
        return {"method": METHOD, "trials_per_distance": self.trials_per_distance, "n_batches": self.batches,
                "include_air": self.include_air, "rows": [dict(r) for r in self.rows],
                "groups": {g: dict(v) for g, v in self.groups.items()},
                "error_rms_m": self.error_rms_m, "error_rms_se_m": self.error_rms_se_m}

    def ranked(self, groups=None) -> list:
        """Rows of ``groups`` (default: those in the combined), largest share first."""
        gs = groups or [g for g in GROUPS if g != "air" or self.include_air]
        return sorted((r for r in self.rows if r["group"] in gs), key=lambda r: -abs(r["share_var_m2"]))


METHOD = ("rows per input quantity; sensitivity: partial derivative at the expectations (central differences), "
          "RMS over the distances; contribution_std_lin_m = |sensitivity| x estimate_std (first order); "
          "contribution_std_mc_m: std of the group's error with only this input varying (JCGM 101 one at a "
          "time), sqrt of the mean over distances of the variance; share_var_m2: Shapley share of the "
          "within-distance variance (pick-freeze), plus one bias row per group (mean square of the mean "
          "error): the shares of a group's rows add up to its error_rms_m squared")


def _draw(dists: dict, names, rng, n) -> dict:
    return {nm: dists[nm].sample(rng, n) for nm in names}


def _oat_at(p, L, group, dists, fixed, n, seed):
    """One-at-a-time std and first-order sensitivities of one group at one distance."""
    col = _GCOL[group]
    q_inputs = _group_inputs_q(dists, p, group)
    model = functools.partial(_group_model, p, float(L), col, fixed)
    ub = mc_budget(model, q_inputs, trials=n, rng=seed)
    std = {c.name: c.std for c in ub.components}
    sens = {c.name: c.sensitivity for c in ub.components}
    if "misalignment" in q_inputs:           # the joint input: both partial derivatives at (0, 0)
        u_th, u_ph = q_inputs["misalignment"].stds()
        held = {k: float(d.mean) for k, d in q_inputs.items() if k != "misalignment"}

        def m2(theta, phi):
            mm = np.stack([theta, phi], axis=-1)
            return model(misalignment=mm, **{k: np.full(theta.shape, v) for k, v in held.items()})

        s = gum_linear(m2, {"theta": Normal(0.0, u_th), "phi": Normal(0.0, u_ph)}).sensitivities
        sens["misalignment"] = (s["theta"], s["phi"])
    return std, sens


def input_budget(inst: Instrument | str = "seed2020", *, head: str = "A", distance_m=None, trials: int = 20_000,
                 rng=None, include_air: bool | None = None, batches: int = 8) -> InputBudget:
    """Per-input budget of one distance measurement, pooled over the instrument's distances.

    Parameters
    ----------
    inst : Instrument or str
    head : str
    distance_m : array_like, optional
        Distances (m); default the instrument's budget grid.
    trials : int
        Trials per distance for each Monte Carlo (one-at-a-time runs and each of the 2^d pick-freeze
        evaluations of a group with d inputs); rounded up to a multiple of ``batches``.
    rng : seed (int, SeedSequence, Generator or None)
        Distance ``i`` runs the one-at-a-time budgets on spawn key ``(0xB1, i)`` and the pick-freeze
        draws on ``(0xB2, i)`` of the root seed.
    include_air : bool, optional
        Whether the air group is in the combined (default from the instrument).
    batches : int
        Batches for the standard errors (batch means; the estimates are those of the whole sample).
    """
    inst = _resolve_inst(inst)
    p = _params(inst, head)
    d = inst.budget.distances_m if distance_m is None else np.atleast_1d(np.asarray(distance_m, dtype=float))
    require_finite("distance_m", d, positive=True)
    if isinstance(trials, bool) or not isinstance(trials, (int, np.integer)) or trials < 2 * batches:
        raise MultilatError(f"trials must be an integer >= {2 * batches}, got {trials!r}")
    n = int(math.ceil(int(trials) / batches) * batches)
    air = inst.budget.include_air if include_air is None else bool(include_air)
    dists = group_inputs(inst, head)
    fixed = _nominal(dists, p)
    root = resolve_seed(rng)
    acc = {g: {"v": 0.0, "bias": 0.0, "oat": {}, "sens": {}} for g in GROUPS}
    means = np.zeros((d.size, len(GROUPS), batches))
    for i, L in enumerate(d):
        ss_oat = np.random.SeedSequence(root.entropy, spawn_key=tuple(root.spawn_key) + (0xB1, i))
        ss_pf = np.random.SeedSequence(root.entropy, spawn_key=tuple(root.spawn_key) + (0xB2, i))
        gen = np.random.default_rng(ss_pf)
        A, B = _draw(dists, dists, gen, n), _draw(dists, dists, gen, n)
        oat_seeds = ss_oat.spawn(len(GROUPS))
        for j, g in enumerate(GROUPS):
            factors = [raw for key, gg, _, _, raw, _ in QUANTITIES if gg == g]
            names = [nm for f in factors for nm in f]
            fx = {k: v for k, v in fixed.items() if k not in names}
            v, bias, mean_a = _closed_indices(p, float(L), j, fx, factors, A, B, batches)
            a = acc[g]
            a["v"] = a["v"] + _shapley(v, len(factors)) / d.size
            a["bias"] = a["bias"] + bias / d.size
            means[i, j] = mean_a
            std, sens = _oat_at(p, L, g, dists, fx, n, oat_seeds[j])
            for k in std:
                a["oat"][k] = a["oat"].get(k, 0.0) + std[k] ** 2 / d.size
                s = sens.get(k)
                if s is not None:
                    prev = a["sens"].get(k, (0.0, 0.0))
                    s = np.asarray(s, dtype=float)
                    a["sens"][k] = (prev[0] + s**2 / d.size, prev[1] + s / d.size)
    return _assemble(inst, head, p, dists, acc, means, air, n, batches)


def _se(x) -> float:
    x = np.asarray(x, dtype=float)
    return float(x.std(ddof=1) / math.sqrt(x.size)) if x.size > 1 else float("nan")


def _row(key, group, sym, desc, unit, dist, a, idx, src) -> dict:
    if isinstance(dist, _Misalignment):
        u = list(dist.stds())
        est = [0.0, 0.0]
    else:
        u, est = float(dist.std), float(dist.mean)
    s2, s1 = a["sens"].get(key, (None, None))
    if isinstance(dist, Constant):            # exact: no derivative taken (a zero step), no contribution
        sens, ugum = None, 0.0
    elif s2 is None:
        sens = ugum = None
    else:
        sens_arr = np.copysign(np.sqrt(s2), s1)
        ugum = float(np.sqrt(np.sum((sens_arr * np.asarray(u)) ** 2)))
        sens = [float(x) for x in sens_arr] if np.ndim(sens_arr) else float(sens_arr)
    share = a["v"][:, idx]
    sh = float(share.mean())
    return {"quantity": key, "symbol": sym, "description": desc, "group": group, "unit": unit, "source": src,
            "distribution": _describe(dist), "estimate": est, "estimate_std": u,
            "sensitivity": sens, "sensitivity_unit": "m" if unit == "1" else f"m/{unit}", "contribution_std_lin_m": ugum,
            "contribution_std_mc_m": float(math.sqrt(a["oat"][key])), "share_var_m2": sh,
            "share_var_se_m2": _se(share), "share_std_m": math.copysign(math.sqrt(abs(sh)), sh)}


def _assemble(inst, head, p, dists, acc, means, air, n, batches) -> InputBudget:
    src = _sources(inst, head)
    rows, groups = [], {}
    for g in GROUPS:
        a = acc[g]
        qs = [q for q in QUANTITIES if q[1] == g]
        for idx, (key, _, sym, desc, raw, unit) in enumerate(qs):
            dist = _Misalignment(p.cone, p.half_angle_rad) if key == "misalignment" else dists[raw[0]]
            rows.append(_row(key, g, sym, desc, unit, dist, a, idx, src[key]))
        b = float(a["bias"].mean())
        rows.append({"quantity": "bias", "symbol": "ē", "group": g, "unit": "m", "source": None,
                     "description": f"mean error of the {g} group (not corrected), mean square over the distances",
                     "distribution": None, "estimate": None, "estimate_std": None, "sensitivity": None,
                     "sensitivity_unit": None, "contribution_std_lin_m": None, "contribution_std_mc_m": None,
                     "share_var_m2": b, "share_var_se_m2": _se(a["bias"]),
                     "share_std_m": math.copysign(math.sqrt(abs(b)), b)})
        tot = a["v"].sum(axis=1) + a["bias"]                # per batch: the group's mean square
        u = math.sqrt(max(float(tot.mean()), 0.0))
        groups[g] = {"error_rms_m": u, "error_rms_se_m": _se(tot) / (2 * u) if u > 0 else 0.0,
                     "error_mean_m": float(means[:, GROUPS.index(g)].mean()),
                     "error_var_m2": float(a["v"].sum(axis=1).mean()), "error_mean_square_m2": b}
    inc = [j for j, g in enumerate(GROUPS) if g != "air" or air]
    tot = sum(acc[GROUPS[j]]["v"].sum(axis=1) + acc[GROUPS[j]]["bias"] for j in inc)
    for x, j in enumerate(inc):                          # cross terms of the groups' means (independent draws)
        for k in inc[x + 1:]:
            tot = tot + 2.0 * (means[:, j] * means[:, k]).mean(axis=0)
    cu = math.sqrt(max(float(tot.mean()), 0.0))
    return InputBudget(rows=rows, groups=groups, error_rms_m=cu, error_rms_se_m=_se(tot) / (2 * cu) if cu else 0.0,
                       include_air=air, trials_per_distance=n, batches=batches)


# ------------------------------------------------------------------ display (shared by the CLI and the report)
_DEG = 180.0 / math.pi
#: display unit and factor (display value = SI value x factor) of each quantity
DISPLAY = {"clock": ("nm/m", 1e9), "xt_phase": ("rad", 1.0), "power_db": ("dB", 1.0), "phase_noise": ("mrad", 1e3),
           "a": ("µm", 1e6), "c": ("µm", 1e6), "alpha": ("°", _DEG), "gamma": ("°", _DEG), "toh": ("µm", 1e6),
           "head_el": ("°", _DEG), "ta": ("µm", 1e6), "tb": ("µm", 1e6), "tc": ("µm", 1e6), "tot": ("µm", 1e6),
           "target_el": ("°", _DEG), "misalignment": ("°", _DEG), "d_t": ("°C", 1.0), "d_p": ("hPa", 1.0),
           "d_rh": ("%RH", 1.0), "d_co2": ("ppm", 1.0)}


def _g(x) -> str:
    return "(" + ", ".join(f"{v:.3g}" for v in x) + ")" if isinstance(x, (list, tuple)) else f"{x:.3g}"


_SHORT = {"clock": "clock δf/f", "xt_phase": "crosstalk ψ", "power_db": "AM/PM ΔP", "phase_noise": "phase noise δΦ",
          "a": "head offset a", "c": "head offset c", "alpha": "head tilt α", "gamma": "head tilt γ",
          "toh": "head transit Toh", "head_el": "head elevation φ", "ta": "target offset a'",
          "tb": "target offset b'", "tc": "target offset c'", "tot": "target transit Tot",
          "target_el": "target elevation φ'", "misalignment": "target misalign θ'',φ''", "d_t": "air T",
          "d_p": "air p", "d_rh": "air RH", "d_co2": "air CO2"}


def row_text(row: dict) -> dict:
    """A row's cells as text in display units (µm for contributions): quantity, short (symbol and a short
    name), distribution, u (u(x) with its unit), sensitivity (µm per display unit), u_gum, u_mc, u_share."""
    def um(v):
        return "-" if v is None else f"{v * 1e6:.2f}"

    share = f"{row['share_std_m'] * 1e6:.2f}"
    if row["quantity"] == "bias":
        return {"quantity": "bias", "short": f"{row['group']} bias", "dist_short": "mean error", "sens_short": "-",
                "distribution": "mean error", "u": "-", "sensitivity": "-",
                "u_gum": "-", "u_mc": "-", "u_share": share}
    du, f = DISPLAY[row["quantity"]]
    d = row["distribution"]
    if d["type"] == "normal":
        dist = f"normal {d['mean'] * f:.3g} ± {d['std'] * f:.3g} {du}"
        short = f"N({d['mean'] * f:.3g}, {d['std'] * f:.3g}) {du}"
    elif d["type"] == "uniform":
        dist = f"uniform [{d['low'] * f:.3g}, {d['high'] * f:.3g}] {du}"
        short = f"U[{d['low'] * f:.3g}, {d['high'] * f:.3g}] {du}"
    elif d["type"] == "constant":
        dist = short = f"constant {d['value'] * f:.3g} {du}"
    else:
        dist = f"{d['type']}, half-angle {d['half_angle_rad'] * _DEG:.3g}°"
        short = ("U cone" if d["type"].endswith("solid angle") else "U square") + f" {d['half_angle_rad'] * _DEG:.3g}°"
    u = row["estimate_std"]
    s = row["sensitivity"]
    uu = [x * f for x in u] if isinstance(u, list) else u * f
    ss = "-" if s is None else _g([x * 1e6 / f for x in s] if isinstance(s, list) else s * 1e6 / f)
    sens_short = ss.strip("()")
    return {"quantity": f"{row['symbol']} {row['description']}", "short": _SHORT[row["quantity"]],
            "distribution": dist, "dist_short": short, "sens_short": sens_short, "u": f"{_g(uu)} {du}",
            "sensitivity": f"{ss} µm/{'(' + du + ')' if '/' in du else du}" if s is not None else "-", "u_gum": um(row["contribution_std_lin_m"]),
            "u_mc": um(row["contribution_std_mc_m"]), "u_share": share}
