"""Two-face (double-centering) estimation of the transit offset from distances."""

import json

import numpy as np
import pytest

from multilat.campaign.twoface import TwoFaceData, estimate_two_face, face_model, read_two_face
from multilat.cli import main
from multilat.errors import MultilatError

TARGETS = [(2.0, 0.1), (5.0, -0.2), (8.0, 0.35)]   # (distance m, elevation rad)


def _simulate(rng, *, toh=3e-6, const=5e-6, sigma=1e-6, reps=3, ref_first=True):
    tg, fc, d, el, ref = [], [], [], [], []
    for j, (R, phi) in enumerate(TARGETS):
        for f in (1, -1):
            for _ in range(reps):
                tg.append(f"T{j}")
                fc.append(f)
                el.append(phi)
                ref.append(R if (ref_first and j == 0) else np.nan)
                d.append(face_model(R + const, toh, f, phi) + rng.normal() * sigma)
    return TwoFaceData(None, tuple(tg), np.array(fc), np.array(d), np.array(el),
                       np.full(len(d), sigma), np.array(ref))


def test_exact_data_recovered():
    data = _simulate(np.random.default_rng(0), sigma=0.0)
    data = TwoFaceData(**{**data.__dict__, "sigma_m": np.full(data.distance_m.size, 1e-6)})
    r = estimate_two_face(data)
    assert r.transit_offset_m == pytest.approx(3e-6, abs=1e-12)
    assert r.constant_m == pytest.approx(5e-6, abs=1e-12)
    np.testing.assert_allclose(r.target_distance_m, [2.000005, 5.000005, 8.000005], atol=1e-12)
    # closed form: face difference = 2 Toh cos(phi) to first order (Toh/R ~ 1e-6)
    d = data.distance_m
    np.testing.assert_allclose(d[0] - d[3], 2 * 3e-6 * np.cos(0.1), rtol=1e-5)


def test_uncertainty_agrees_with_scatter():
    # 400 simulated two-face sessions: the reported sigma of Toh and C match the scatter, and
    # chi2 has mean dof. Tolerances: the relative standard error of a std from n=400 is 1/sqrt(2n)
    # = 3.5 %, so 15 % is > 4 standard errors; mean chi2 has standard error sqrt(2 dof / n).
    rng = np.random.default_rng(7)
    est, std, cst, cstd, chi2 = [], [], [], [], []
    for _ in range(400):
        r = estimate_two_face(_simulate(rng))
        est.append(r.transit_offset_m)
        std.append(r.transit_offset_std_m)
        cst.append(r.constant_m)
        cstd.append(r.constant_std_m)
        chi2.append(r.chi2)
        dof = r.dof
    est, cst = np.array(est), np.array(cst)
    assert abs(est.mean() - 3e-6) < 4 * std[0] / np.sqrt(400)
    assert np.std(est, ddof=1) / std[0] == pytest.approx(1.0, abs=0.15)
    assert np.std(cst, ddof=1) / cstd[0] == pytest.approx(1.0, abs=0.15)
    assert np.mean(chi2) == pytest.approx(dof, abs=4 * np.sqrt(2 * dof / 400))


def test_without_reference_only_toh_and_without_sigma_scaled():
    rng = np.random.default_rng(3)
    data = _simulate(rng, ref_first=False)
    r = estimate_two_face(data)
    assert r.constant_m is None and "constant" not in r.parameters
    assert abs(r.transit_offset_m - 3e-6) < 5 * r.transit_offset_std_m
    r2 = estimate_two_face(TwoFaceData(**{**data.__dict__, "sigma_m": None}))
    assert r2.scaled and r2.transit_offset_m == pytest.approx(r.transit_offset_m, abs=1e-15)
    np.testing.assert_allclose(r2.transit_offset_std_m, r.transit_offset_std_m * r.sigma0, rtol=1e-9)


def test_unobservable_cases():
    one_face = TwoFaceData(None, ("T", "T"), np.array([1, 1]), np.array([2.0, 2.0]), np.array([0.1, 0.1]),
                           np.array([1e-6, 1e-6]), np.full(2, np.nan))
    with pytest.raises(MultilatError, match="transit offset not observable"):
        estimate_two_face(one_face)
    vertical = TwoFaceData(None, ("T", "T"), np.array([1, -1]), np.array([2.0, 2.0]),
                           np.array([np.pi / 2, np.pi / 2]), np.array([1e-6, 1e-6]), np.full(2, np.nan))
    with pytest.raises(MultilatError, match="not observable"):
        estimate_two_face(vertical)


def test_cli_two_face(tmp_path, capsys):
    data = _simulate(np.random.default_rng(11))
    rows = ["head,target,face,distance_m,elevation_rad,sigma_m,reference_distance_m"]
    for i in range(data.distance_m.size):
        ref = "" if np.isnan(data.reference_distance_m[i]) else repr(float(data.reference_distance_m[i]))
        rows.append(f"A,{data.target_ids[i]},{'I' if data.face[i] > 0 else 'II'},{float(data.distance_m[i])!r},"
                    f"{float(data.elevation_rad[i])!r},1e-6,{ref}")
    p = tmp_path / "faces.csv"
    p.write_text("\n".join(rows) + "\n")
    assert main(["two-face", str(p), "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    r = estimate_two_face(read_two_face(p))
    assert out["transit_offset_m"] == pytest.approx(r.transit_offset_m, rel=1e-12)
    assert out["head"] == "A"
    assert main(["two-face", str(p)]) == 0
    assert "transit offset" in capsys.readouterr().out.lower()
    # --sigma-um overrides the file's sigma_m: the estimate is unchanged (uniform weights) and its
    # uncertainty scales linearly with sigma
    assert main(["two-face", str(p), "--sigma-um", "2", "--json"]) == 0
    out2 = json.loads(capsys.readouterr().out)
    assert out2["transit_offset_m"] == pytest.approx(out["transit_offset_m"], rel=1e-9)
    assert out2["transit_offset_std_m"] == pytest.approx(2 * out["transit_offset_std_m"], rel=1e-9)
    assert main(["two-face", str(p), "--sigma-um", "-1"]) == 2
    assert "--sigma-um" in capsys.readouterr().err
    p.write_text(rows[0] + "\n" + rows[1].replace(",I,", ",III,") + "\n")
    assert main(["two-face", str(p)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "faces.csv:2: column 'face'" in err[0]


def test_against_3d_gimbal_geometry():
    # Face I at elevation phi, face II through the zenith (phi -> pi - phi) with the explicit 3D head
    # of multilat.gimbal (beam offsets and tilts of Table III size): the face difference gives Toh,
    # and the beam-offset/tilt term is the same in both faces, lumped into the constant C.
    from multilat import gimbal

    kw = dict(a_m=190e-6, c_m=-230e-6, alpha_rad=np.radians(0.12), gamma_rad=np.radians(-0.09))
    toh = -3e-6
    tg, fc, d, el, ref = [], [], [], [], []
    for j, (R, phi) in enumerate(TARGETS):
        for f, ang in ((1, phi), (-1, np.pi - phi)):
            tg.append(f"T{j}")
            fc.append(f)
            el.append(phi)
            ref.append(R)
            d.append(float(gimbal.head_measured_distance_3d(R, toh_m=toh, elevation_rad=ang, **kw)))
    data = TwoFaceData("B", tuple(tg), np.array(fc), np.array(d), np.array(el), np.full(len(d), 1e-6),
                       np.array(ref))
    r = estimate_two_face(data)
    # beam term with no transit offset, same in both faces (to 1e-12 m)
    b1 = gimbal.head_measured_distance_3d(5.0, toh_m=0.0, elevation_rad=0.3, **kw) - 5.0
    b2 = gimbal.head_measured_distance_3d(5.0, toh_m=0.0, elevation_rad=np.pi - 0.3, **kw) - 5.0
    assert abs(b1 - b2) < 1e-12
    # Toh recovered to second order (Toh x tilt ~ 1e-11 m); C = a sin(alpha) + c sin(gamma) - ...
    assert r.transit_offset_m == pytest.approx(toh, abs=1e-10)
    first_order = kw["a_m"] * np.sin(kw["alpha_rad"]) + kw["c_m"] * np.sin(kw["gamma_rad"])
    assert r.constant_m == pytest.approx(float(b1), abs=2e-8)      # 1/R term: (a²+c²)/2R < 2e-8 m
    assert r.constant_m == pytest.approx(first_order, abs=2e-8)
