"""``multilat export`` and ``multilat import``: the network in the files of GNU Gama (gama-local
XML, and its adjusted XML output), JAG3D (flat-file import) and Star*Net (.dat). See
docs/interop.md."""

from __future__ import annotations

from pathlib import Path
from typing import Optional

import typer

from multilat.cli import checks
from multilat.cli.app import app, console, emit_json
from multilat.errors import MultilatError
from multilat.io import check_not_input

EXPORT_FORMATS = ("gama", "jag3d", "starnet")
IMPORT_FORMATS = ("gama", "gama-adjusted", "jag3d", "starnet")


def _fixed_ids(text: str | None) -> tuple[str, ...]:
    if not text:
        return ()
    ids = tuple(t.strip() for t in text.split(","))
    if any(not t for t in ids):
        raise MultilatError(f"--fix: empty point id in {text!r}")
    return ids


@app.command("export")
def export_command(
    fmt: str = typer.Argument(..., metavar="FORMAT", help="gama (gama-local XML), jag3d (flat "
                              "files: OUT and OUT's name with -points) or starnet (.dat)."),
    observations: Path = typer.Argument(..., help="Observations CSV: station,target,distance_m[,sigma_m]."),
    out: Path = typer.Option(..., "--out", "-o", help="File to write (written whole or not at all)."),
    points: Optional[Path] = typer.Option(None, "--points", help="Points CSV: point,x_m,y_m,z_m "
                                          "(approximate coordinates; gama and jag3d need every point)."),
    result: Optional[Path] = typer.Option(None, "--result", help="The --out directory of `multilat "
                                          "adjust`: its adjusted coordinates (approximate values) and, "
                                          "for gama and starnet, its offsets (fixed, subtracted from "
                                          "the distances; jag3d keeps them as unknowns)."),
    offsets_um: Optional[str] = typer.Option(None, "--offsets-um", help="Fixed station offsets, µm: "
                                             "one value for all or A=1234,B=-871,... (every station), "
                                             "subtracted from the distances (any format)."),
    fix: Optional[str] = typer.Option(None, "--fix", help="Points held fixed in the tool (gama, "
                                      "starnet): P1,P2,... Default gama: a free network over all "
                                      "points; starnet: none (Star*Net then needs a datum)."),
    sigma_um: Optional[float] = typer.Option(None, "--sigma-um", help="σ of every distance, µm, "
                                             "when the CSV has no sigma_m column."),
    levelled: Optional[str] = typer.Option(None, "--levelled", help="Stations on their level: their "
                                           "angles become directions (one orientation) and zenith angles; "
                                           "the three formats' angles need levelled stations: ID,ID,..."),
    as_json: bool = typer.Option(False, "--json", help="Print what was written as JSON."),
) -> None:
    """Write the network for GNU Gama, JAG3D or Star*Net. What a format cannot carry (a per-station
    additive offset in Gama and Star*Net) is applied as a fixed correction or refused."""
    from multilat.cli.network_cmd import parse_fixed_offsets, with_levelled
    from multilat.network.io.files import read_observations, read_points
    from multilat.network.io.interop.common import read_result_dir

    if fmt not in EXPORT_FORMATS:
        raise MultilatError(f"export FORMAT must be one of {', '.join(EXPORT_FORMATS)}, got {fmt!r}")
    checks.sigma_um(sigma_um)
    if points is not None and result is not None:
        raise MultilatError("give --points or --result, not both")
    obs = read_observations(observations, sigma_m=None if sigma_um is None else sigma_um * 1e-6)
    obs = with_levelled(obs, levelled)
    offsets, scales = None, None
    pts = read_points(points) if points is not None else None
    if result is not None:
        from multilat.network.io.interop.angles import refuse_tilted_result

        pts, offsets, scales = read_result_dir(result)
        refuse_tilted_result(obs, result, fmt)
        if fmt == "jag3d":
            offsets = None        # JAG3D estimates them itself (one zero-point offset per group = head)
    if offsets_um is not None:
        what = "head" if obs.station_heads is not None else "station"
        offsets = parse_fixed_offsets(offsets_um, obs.head_ids, what=what)
        if isinstance(offsets, dict) and set(offsets) != set(obs.head_ids):
            missing = [s for s in obs.head_ids if s not in offsets][0]
            raise MultilatError(f"--offsets-um: no value for {what} {missing!r}; give every {what}'s")
    fixed = _fixed_ids(fix)
    inputs = [observations, points] + ([result / n for n in ("stations.csv", "targets.csv", "points.csv", "result.json")]
                                       if result else [])
    written = [out]
    if fmt == "gama":
        from multilat.network.io.interop.gama import write_gama_local

        check_not_input(out, inputs)
        write_gama_local(out, obs, pts if pts is not None else _no_points(), offsets=offsets,
                         fixed=fixed, description=f"multilat export of {observations.name}", scales=scales)
    elif fmt == "jag3d":
        from multilat.network.io.interop.jag3d import write_jag3d

        if fixed:
            raise MultilatError("--fix: JAG3D's point type (reference/datum/new) is chosen on its "
                                "import, not in the file")
        from multilat.network.io.interop.jag3d import jag3d_files

        p_out = out.with_name(out.stem + "-points" + (out.suffix or ".txt"))
        for w in [*jag3d_files(out, obs), p_out]:
            check_not_input(w, inputs)
        written = write_jag3d(p_out, out, obs, pts, offsets=offsets, scales=scales) + [p_out]
    else:
        from multilat.network.io.interop.starnet import write_starnet

        check_not_input(out, inputs)
        write_starnet(out, obs, pts, offsets=offsets, fixed=fixed, scales=scales)
    doc = {"format": fmt, "files": [str(w) for w in written], "n_obs": obs.n_obs,
           "n_stations": obs.n_stations, "n_targets": obs.n_targets,
           "n_angles": _n_angles(obs), "offsets_subtracted": offsets is not None,
           "heads": {h: [s for s, g in zip(obs.station_ids, obs.head_of_station) if g == h] for h in obs.head_ids}}
    if as_json:
        emit_json(doc, "export")
        return
    console.print(f"{fmt}: {obs.n_obs} distances, {obs.n_stations} stations ({len(obs.head_ids)} heads), "
                  f"{obs.n_targets} targets -> {', '.join(str(w) for w in written)}")


def _n_angles(obs) -> int:
    import numpy as np

    return int(sum(np.isfinite(v).sum() for v in (obs.sigma_azimuth_rad, obs.sigma_elevation_rad) if v is not None))


def _no_points():
    import numpy as np

    from multilat.network.model.data import Points

    return Points((), np.zeros((0, 3)))


@app.command("import")
def import_command(
    fmt: str = typer.Argument(..., metavar="FORMAT", help="gama (gama-local XML input), "
                              "gama-adjusted (gama-local's --xml output), jag3d (slope distances; "
                              "with --points-file) or starnet (.dat)."),
    source: list[Path] = typer.Argument(..., help="The file to read (jag3d: its observation files: distances, "
                                        "one per head; directions; zenith angles)."),
    out: Path = typer.Option(..., "--out", "-o", help="Directory for distances.csv and points.csv "
                             "(gama-adjusted: points.csv, residuals.csv, summary.json; gama: "
                             "observations.csv, points.csv, covariances.csv and distances.csv where they apply, for "
                             "`multilat adjust DIR`), written all or nothing."),
    points_file: Optional[Path] = typer.Option(None, "--points-file", help="jag3d: the points file "
                                               "(NAME Y X Z)."),
    sigma_um: Optional[float] = typer.Option(None, "--sigma-um", help="σ, µm, for distances without "
                                             "one in the file (jag3d, starnet)."),
    as_json: bool = typer.Option(False, "--json", help="Print a summary as JSON."),
) -> None:
    """Read a network (or gama-local's adjusted result) from GNU Gama, JAG3D or Star*Net files into
    multilat's CSVs (`multilat adjust OUT/distances.csv --points OUT/points.csv`)."""
    from multilat.io import staging_dir, write_csv_atomic, write_json_atomic
    from multilat.network.io.files import write_observations

    if fmt not in IMPORT_FORMATS:
        raise MultilatError(f"import FORMAT must be one of {', '.join(IMPORT_FORMATS)}, got {fmt!r}")
    checks.sigma_um(sigma_um)
    sources, source = source, source[0]
    if len(sources) > 1 and fmt != "jag3d":
        raise MultilatError(f"import {fmt} reads one file, got {len(sources)} (several: jag3d's distance files)")
    sig = None if sigma_um is None else sigma_um * 1e-6
    if (points_file is not None) != (fmt == "jag3d"):
        raise MultilatError("--points-file goes with jag3d (and jag3d needs it)")
    if fmt == "gama-adjusted":
        from multilat.network.io.interop.gama_adjusted import read_gama_adjustment

        g = read_gama_adjustment(source)
        doc = {"format": fmt, "dof": g.dof, "defect": g.defect, "sigma0": g.sigma_aposteriori,
               "sigma0_apriori": g.sigma_apriori, "n_obs": len(g.station), "n_points": len(g.ids),
               "fixed": list(g.fixed)}
        with staging_dir(out, inputs=[source]) as tmp:
            write_csv_atomic(tmp / "points.csv", ["point", "x_m", "y_m", "z_m"],
                             [[i, *x] for i, x in zip(g.ids, g.xyz_m)])
            write_csv_atomic(tmp / "residuals.csv",
                             ["station", "target", "distance_m", "adjusted_m", "residual_m",
                              "adjusted_std_m", "redundancy", "w_abs"],
                             [[s, t, d, a, r, u, q, w] for s, t, d, a, r, u, q, w in
                              zip(g.station, g.target, g.observed_m, g.adjusted_m, g.residual_m,
                                  g.adjusted_std_m, g.redundancy, g.std_residual)])
            if g.angles is not None:
                a = g.angles
                write_csv_atomic(tmp / "angle_residuals.csv",
                                 ["station", "target", "kind", "value_rad", "adjusted_rad", "residual_rad",
                                  "adjusted_std_rad", "w_abs"],
                                 [[s, t, k, v, ad, r, u, w] for s, t, k, v, ad, r, u, w in
                                  zip(a.station, a.target, a.kind, a.observed_rad, a.adjusted_rad, a.residual_rad,
                                      a.adjusted_std_rad, a.std_residual)])
                doc["n_angles"] = len(a.kind)
                doc["stations"] = {k: {"orientation_rad": v, "orientation_std_rad": g.orientation_std_rad.get(k)}
                                   for k, v in g.orientation_rad.items()}
            from multilat.vocabulary import stamp

            doc = stamp(doc, "import")
            write_json_atomic(tmp / "summary.json", doc)
        if as_json:
            emit_json(doc, "import")
        else:
            console.print(f"gama-local result: {doc['n_obs']} slope distances, {doc['n_points']} "
                          f"points, dof {g.dof}, sigma0 {g.sigma_aposteriori:.4f} -> {out}")
        return
    if fmt == "gama":
        return _import_gama(source, out, as_json)       # the general network's files (docs/interop.md)
    if fmt == "jag3d":
        from multilat.network.io.interop.jag3d import read_jag3d

        net = read_jag3d(points_file, sources, sigma_m=sig)
    else:
        from multilat.network.io.interop.starnet import read_starnet

        net = read_starnet(source, sigma_m=sig)
    o = net.obs
    doc = {"format": fmt, "n_obs": o.n_obs, "n_stations": o.n_stations, "n_targets": o.n_targets,
           "n_angles": _n_angles(o), "levelled": list(o.levelled), "n_heads": len(o.head_ids),
           "n_points": len(net.points.ids), "fixed": list(net.fixed), "notes": list(net.notes)}
    with staging_dir(out, inputs=[*sources, points_file]) as tmp:
        write_observations(tmp / "distances.csv", o)
        write_csv_atomic(tmp / "points.csv", ["point", "x_m", "y_m", "z_m"],
                         [[i, *x] for i, x in zip(net.points.ids, net.points.xyz_m)])
    if as_json:
        emit_json(doc, "import")
        return
    console.print(f"{fmt}: {o.n_obs} distances, {o.n_stations} stations, {o.n_targets} targets, "
                  f"{len(net.points.ids)} points with coordinates -> {out}")
    for n in net.notes:
        console.print(f"note: {n}")
    if net.fixed:
        console.print(f"note: the file holds {', '.join(net.fixed)} fixed: adjust with --datum "
                      f"control:{','.join(net.fixed)} to keep them")


def _restored_general(old, source: Path):
    """The general network of a multilat export read back with its model restored (``old``: the
    interop reader's network): one instrument per head with its offset estimated, levelled stations'
    angles, the file's fixed points held (:func:`~multilat.network.adjust.general.from_tables.network_from_tables`,
    the mapping ``adjust obs.csv --model general`` uses)."""
    from multilat.network.adjust.general.from_tables import network_from_tables

    import dataclasses

    import numpy as np

    datum = f"control:{','.join(old.fixed)}" if old.fixed else "free"
    net = network_from_tables(old.obs, points=old.points, datum=datum, source=source.name)[0]
    if not old.fixed:                                  # free: every point a datum point, as the file's reading
        pts = dataclasses.replace(net.points, constrained=np.ones(net.points.n, bool))
        net = dataclasses.replace(net, points=pts)
    return net


def _import_gama(source: Path, out: Path, as_json: bool) -> None:
    """``import gama``: the whole network as multilat's files for the general network
    (observations.csv, points.csv, covariances.csv: every kind, σ, heights, partly fixed points;
    ``multilat adjust OUT``) and, when the distance path's reader takes the file (slope distances,
    levelled stations' angles), its distances.csv as before, all or nothing."""
    import numpy as np

    from multilat.io import staging_dir
    from multilat.network.io.files import write_observations
    from multilat.network.adjust.general import FIXED, read_gama_input
    from multilat.network.io.general_files import write_network_files
    from multilat.network.model.kinds import KINDS
    from multilat.network.io.interop.gama import read_gama_local

    net = read_gama_input(source)
    try:
        old = read_gama_local(source)
    except MultilatError as e:                          # e.g. heights, partly fixed points: general files only
        old, why = None, str(e)
    bare = [p for p, x in zip(net.points.ids, net.points.xyz_m) if not np.isfinite(x).all()]
    if old is not None and bare:                        # points.csv would not be the distance path's --points
        old, why = None, f"{len(bare)} point(s) without coordinates ({bare[0]}, ...), which its --points needs"
    doc = {"format": "gama", "n_obs": net.n_rows, "n_points": net.points.n,
           "fixed": [p for p, s in zip(net.points.ids, net.points.status) if (s == FIXED).any()],
           "n_angles": sum(b.n_rows for b in net.blocks if KINDS[b.kind].UNIT == "rad"), "notes": list(net.notes)}
    if old is not None and old.restored:               # a multilat export: its heads and offsets, not Gama's model
        net = _restored_general(old, source)
        doc["notes"].append("observations.csv: the file's multilat-heads/-offsets lines applied: the heads' "
                            "offsets are unknowns again, as in distances.csv")
    with staging_dir(out, inputs=[source]) as tmp:
        written = write_network_files(net, tmp, comments=[f"imported from {source.name} by multilat import gama",
                                                          *net.notes])
        if old is not None:
            write_observations(tmp / "distances.csv", old.obs)
            written.append("distances.csv")
            doc.update(n_stations=old.obs.n_stations, n_targets=old.obs.n_targets, levelled=list(old.obs.levelled))
            doc["notes"] += [f"distances.csv: {n}" for n in old.notes]
            if old.fixed:
                doc["notes"].append(f"distances.csv: the file holds {', '.join(old.fixed)} fixed: adjust it with "
                                    f"--datum control:{','.join(old.fixed)} to keep them")
        else:
            doc["notes"].append(f"no distances.csv (the distance path cannot take this file: {why})")
    if as_json:
        emit_json(doc, "import")
        return
    console.print(f"gama: {net.n_rows} observation rows, {net.points.n} points -> {out} ({', '.join(written)}; "
                  f"multilat adjust {out})", markup=False)
    for n in doc["notes"]:
        console.print(f"note: {n}", markup=False)
