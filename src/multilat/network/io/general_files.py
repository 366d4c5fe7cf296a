"""multilat's files for the general network: a directory holding ``points.csv``,
``observations.csv`` and, when a block is correlated, ``covariances.csv``
(``docs/general-network.md``, "multilat's files for the general network").

* ``points.csv``: one row per point: ``point,x_m,y_m,z_m[,fixed][,sx_m,sy_m,sz_m][,datum]``;
  empty coordinates are unknown yet (computed from the observations), ``fixed`` the letters of the
  held coordinates (``xyz``, ``xy``, ``z``), a coordinate with a σ (``sx_m`` ...) is weighted,
  ``datum`` = ``true`` marks a datum point of a free network.
* ``observations.csv``: one row per observation row, in long form, as a field book: ``kind``,
  ``block`` (optional), ``value``, ``sigma``, ``unit`` (``m`` or ``rad``, the kind's) and the
  columns the kind declares (``COLUMNS`` of each module of :mod:`.kinds`: ``from``, ``to``,
  ``set``, ``from_dh_m`` ...). Rows with the same ``block`` id form one block (one covariance,
  one value of the kind's options); rows without one are grouped by kind (and options).
* ``covariances.csv``: ``block,row,col,cov``: the covariance of a correlated block (the square of
  its unit: m², rad²), ``row``, ``col`` 1-based positions among the block's rows in file order;
  the upper or the lower triangle (an entry and its mirror image is one given twice), zeros may be
  left out, every variance must be there.

Inside: multilat's frame (x east, y north, z up), metres and radians, directions and angles
counter-clockwise (a reader of another format converts on import). Everything of a
:class:`~.observations.Network` is written (points and their status, every block's rows, values,
σ, covariances, references, heights, options): ``read_network_dir(write_network_dir(net))`` is
``net`` up to its labels (the files' ``FILE:LINE``) and notes, with the ids of direction sets,
instruments and set-ups numbered in order of first appearance in their block.

Every bad cell, row or entry is one line ``FILE:LINE: ...`` (:mod:`multilat.inputs`).
"""

from __future__ import annotations

import csv
import io as _io
import os
from pathlib import Path

import numpy as np

from multilat.errors import MultilatError
from multilat.inputs import read_csv_table
from multilat.network.model.kinds import KINDS
from multilat.network.model.kinds.columns import BOOLEANS, Rows
from multilat.network.model.observations import Network
from multilat.network.model.points import FIXED, FREE, WEIGHTED, PointSet

__all__ = ["OBSERVATIONS", "POINTS", "COVARIANCES", "is_network_dir", "read_network_dir", "write_network_dir",
           "write_network_files", "columns_markdown"]

OBSERVATIONS, POINTS, COVARIANCES = "observations.csv", "points.csv", "covariances.csv"
#: the columns of observations.csv every kind has (besides its own value, sigma)
COMMON = ("kind", "block", "unit")
#: points.csv: (column, meaning)
POINT_COLUMNS = (
    ("point", "the point's id (required)"),
    ("x_m", "x (east), m: approximate (free) or given (fixed, weighted); empty: none yet, computed from the "
            "observations (required column)"),
    ("y_m", "y (north), m, as x_m (required column)"),
    ("z_m", "z (up), m, as x_m (required column)"),
    ("fixed", "the coordinates held at their value: letters of x, y, z (`xyz`, `xy`, `z`, ...); empty: none"),
    ("sx_m", "standard deviation of a weighted x, m (> 0): the coordinate is observed at its value; empty: "
             "not weighted"),
    ("sy_m", "as sx_m for y"),
    ("sz_m", "as sx_m for z"),
    ("datum", "`true`: a datum point of a free network (minimum trace over its free coordinates); default "
              "`false`"),
)
#: covariances.csv: (column, meaning)
COVARIANCE_COLUMNS = (
    ("block", "the `block` id of the correlated rows in observations.csv"),
    ("row", "1-based position of a row among the block's rows (file order)"),
    ("col", "1-based position of the other row"),
    ("cov", "the covariance, the square of the block's unit (m², rad²); every variance (row = col) given, "
            "one triangle, zeros may be left out"),
)
_STD = ("sx_m", "sy_m", "sz_m")


def _kind_columns() -> list[str]:
    """Every column of observations.csv, in the order they are written."""
    cols = {c.name: c.role for k in KINDS.values() for c in k.COLUMNS}
    order = {"point": 0, "name": 1, "enum": 1, "value": 2, "sigma": 2, "number": 3, "option": 4}
    refs = [n for n, r in cols.items() if order[r] < 2]
    return ["kind", "block", *refs, "value", "sigma", "unit",
            *[n for n, r in cols.items() if order[r] == 3], *[n for n, r in cols.items() if order[r] == 4]]


def is_network_dir(path) -> bool:
    """True for a directory (a network directory holds observations.csv and points.csv)."""
    return Path(path).is_dir()


# ------------------------------------------------------------------------------------------- read
def read_network_dir(path: str | os.PathLike) -> Network:
    """The :class:`Network` of a directory of multilat's files (module docstring)."""
    d = Path(path)
    for name in (POINTS, OBSERVATIONS):
        if not (d / name).is_file():
            raise MultilatError(f"{d}: is a directory without {name} (a network directory holds {POINTS}, "
                                f"{OBSERVATIONS} and, for correlated blocks, {COVARIANCES}: docs/general-network.md)")
    points = read_points_table(d / POINTS)
    ix = {p: i for i, p in enumerate(points.ids)}
    tab, groups = _observation_groups(d / OBSERVATIONS)
    covs = _read_covariances(d / COVARIANCES, tab, groups) if (d / COVARIANCES).exists() else {}
    value = tab.floats("value")
    sigma = tab.floats("sigma", positive=True, required=False)
    where = [f"{tab.path}:{ln}" for ln in tab.line_numbers]
    blocks = []
    for key, rows in groups.items():
        kind = KINDS[tab.rows[rows[0]][tab.columns.index("kind")]]
        cov = covs.get(key)
        sg = sigma[rows]
        if cov is None:
            if np.isnan(sg).any():
                k = rows[int(np.flatnonzero(np.isnan(sg))[0])]
                raise tab.error(k, "column 'sigma': empty, and its block has no covariances in "
                                   f"{COVARIANCES} (give sigma > 0)")
        else:
            sg = _sigma_of_cov(tab, rows, sg, cov)
        cells = {}
        for c in kind.COLUMNS:
            if tab.has(c.name):
                i = tab.columns.index(c.name)
                cells[c.name] = [tab.rows[k][i] for k in rows]
        blocks.append(kind.from_rows(Rows(cells, tuple(where[k] for k in rows), ix, value[rows], sg, cov)))
    return Network(points, tuple(blocks))


def _observation_groups(path: Path):
    """observations.csv as a table and its rows grouped into blocks (first appearance order):
    ``{key: [row, ...]}``; every row checked against its kind's columns and unit."""
    known = _kind_columns()
    _check_header(path, known)
    tab = read_csv_table(path, required=("kind", "value", "sigma", "unit"), optional=known, warn_unknown=False,
                         numbers={"value": {}, "sigma": dict(positive=True, required=False)}, kind="observations")
    col = {c: i for i, c in enumerate(tab.columns)}
    own = {name: {c.name for c in k.COLUMNS} | set(COMMON) for name, k in KINDS.items()}
    options = {name: [col[c.name] for c in k.COLUMNS if c.role == "option" and c.name in col]
               for name, k in KINDS.items()}
    foreign = {name: [(i, c) for c, i in col.items() if c not in own[name]] for name in KINDS}
    groups: dict = {}
    first_kind: dict = {}
    b_col = col.get("block")
    for k, r in enumerate(tab.rows):
        kd = r[col["kind"]]
        kind = KINDS.get(kd)
        if kind is None:
            raise tab.error(k, f"unknown observation kind {kd!r} (known: {', '.join(KINDS)})")
        if r[col["unit"]] != kind.UNIT:
            raise tab.error(k, f"column 'unit': a {kd} is in {kind.UNIT}, got {r[col['unit']]!r} (the files hold "
                               "metres and radians)")
        for i, name in foreign[kd]:
            if r[i] != "":
                raise tab.error(k, f"column {name!r} does not apply to a {kd} (its columns: "
                                   f"{', '.join(c.name for c in kind.COLUMNS)})")
        b = r[b_col] if b_col is not None else ""
        if b:
            key = ("block", b)
            seen = first_kind.setdefault(b, (kd, k))
            if seen[0] != kd:
                raise tab.error(k, f"block {b!r} holds a {seen[0]} (line {tab.line_numbers[seen[1]]}) and a {kd}: "
                                   "a block is of one kind")
        else:
            key = ("kind", kd, tuple(r[i].lower() for i in options[kd]))
        groups.setdefault(key, []).append(k)
    return tab, {key: np.array(v, int) for key, v in groups.items()}


def _check_header(path, known) -> None:
    """A column of the header that is not one of ``known`` is ``FILE:LINE: unknown column`` (before
    any row is read: a misspelt column is never ignored)."""
    from multilat.inputs import input_lines

    for n, ln in input_lines(path):
        if ln.strip() and not ln.lstrip().startswith("#"):
            stray = [c.strip() for c in next(csv.reader([ln])) if c.strip() not in known]
            if stray:
                raise MultilatError(f"{path}:{n}: unknown column {stray[0]!r} (the columns of {Path(path).name}: "
                                    f"{', '.join(known)}; docs/general-network.md)")
            return


def _read_covariances(path: Path, obs, groups) -> dict:
    """The covariance matrices of covariances.csv, by group key; every entry checked (FILE:LINE)."""
    _check_header(path, [c for c, _ in COVARIANCE_COLUMNS])
    tab = read_csv_table(path, required=("block", "row", "col", "cov"), warn_unknown=False,
                         numbers={"cov": {}, "row": {}, "col": {}}, kind="observations")
    vals = tab.floats("cov")
    rc = np.column_stack([tab.floats("row"), tab.floats("col")])
    entries: dict = {}
    for k, b in enumerate(tab.ids("block")):
        rows = groups.get(("block", b))
        if rows is None:
            raise tab.error(k, f"block {b!r} is not a block id of {OBSERVATIONS}")
        n = len(rows)
        i, j = rc[k]
        if not (i == int(i) and j == int(j) and 1 <= i <= n and 1 <= j <= n):
            raise tab.error(k, f"row {i:g}, col {j:g}: block {b!r} has rows 1..{n}")
        e = entries.setdefault(b, {})
        pair = (min(int(i), int(j)) - 1, max(int(i), int(j)) - 1)
        if pair in e:
            raise tab.error(k, f"block {b!r} entry ({pair[0] + 1}, {pair[1] + 1}) given twice (first at line "
                               f"{tab.line_numbers[e[pair][1]]})")
        if pair[0] == pair[1] and not vals[k] > 0:
            raise tab.error(k, f"column 'cov': a variance must be > 0, got {float(vals[k])!r}")
        e[pair] = (vals[k], k)
    out = {}
    for b, e in entries.items():
        rows = groups[("block", b)]
        n = len(rows)
        c = np.zeros((n, n))
        for (i, j), (v, _) in e.items():
            c[i, j] = c[j, i] = v
        missing = [i for i in range(n) if (i, i) not in e]
        if missing:
            raise obs.error(rows[missing[0]], f"block {b!r}: this row (its row {missing[0] + 1}) has no variance in "
                                              f"{path}")
        _check_definite(tab, b, c, e)
        out[("block", b)] = c
    return out


def _check_definite(tab, b, c, e) -> None:
    """A covariance that is not positive definite is named at the variance of the first row whose
    leading block is not (Cholesky's pivot)."""
    from scipy.linalg import lapack

    _, info = lapack.dpotrf(c, lower=1, clean=0)
    if info > 0:
        k = e[(info - 1, info - 1)][1]
        raise tab.error(k, f"the covariance of block {b!r} is not positive definite (its first {info} row(s))")


def _sigma_of_cov(tab, rows, sg, cov) -> np.ndarray:
    """The σ of a correlated block's rows: the cells given agree with its variances (1e-9 relative)."""
    sd = np.sqrt(np.diag(cov))
    given = ~np.isnan(sg)
    bad = np.flatnonzero(given & ~(np.abs(sg - sd) <= 1e-9 * sd))
    if bad.size:
        raise tab.error(rows[bad[0]], f"column 'sigma': {float(sg[bad[0]])!r}, but its variance in {COVARIANCES} "
                                      f"gives {float(sd[bad[0]])!r} (leave it empty or make them agree)")
    return np.where(given, sg, sd)


def read_points_table(path: str | os.PathLike) -> PointSet:
    """The :class:`PointSet` of a points.csv (module docstring; every bad row ``FILE:LINE``)."""
    names = [c for c, _ in POINT_COLUMNS]
    nums = {c: dict(required=False) for c in ("x_m", "y_m", "z_m")}
    nums.update({c: dict(required=False, positive=True) for c in _STD})
    _check_header(path, names)
    tab = read_csv_table(path, required=("point", "x_m", "y_m", "z_m"), optional=names, warn_unknown=False,
                         numbers=nums)
    ids = tab.ids("point")
    xyz = np.column_stack([tab.floats(c, required=False) for c in ("x_m", "y_m", "z_m")])
    sd = np.column_stack([tab.floats(c, required=False, positive=True) if tab.has(c) else np.full(len(ids), np.nan)
                          for c in _STD])
    fixed = tab.column("fixed") if tab.has("fixed") else [""] * len(ids)
    datum = tab.column("datum") if tab.has("datum") else [""] * len(ids)
    status = np.full((len(ids), 3), FREE)
    constrained = np.zeros(len(ids), bool)
    seen: dict = {}
    for k, p in enumerate(ids):
        if p in seen:
            raise tab.error(k, f"point {p!r} given twice (first at line {tab.line_numbers[seen[p]]})")
        seen[p] = k
        f = fixed[k]
        if any(ch not in "xyz" for ch in f) or len(set(f)) != len(f):
            raise tab.error(k, f"column 'fixed': the letters of the held coordinates (x, y, z, each once), got {f!r}")
        for a in range(3):
            if "xyz"[a] in f:
                status[k, a] = FIXED
                if not np.isnan(sd[k, a]):
                    raise tab.error(k, f"point {p!r}: {'xyz'[a]} is fixed and has {_STD[a]}: a coordinate is "
                                       "fixed or weighted")
            elif not np.isnan(sd[k, a]):
                status[k, a] = WEIGHTED
            if status[k, a] != FREE and np.isnan(xyz[k, a]):
                raise tab.error(k, f"point {p!r}: its {'xyz'[a]} is {'fixed' if status[k, a] == FIXED else 'weighted'}"
                                   f" but column '{'xyz'[a]}_m' is empty")
        v = BOOLEANS.get(datum[k].lower()) if datum[k] else False
        if v is None:
            raise tab.error(k, f"column 'datum' must be true or false, got {datum[k]!r}")
        constrained[k] = v
    return PointSet(tuple(ids), xyz, status, sd, constrained)


# ------------------------------------------------------------------------------------------ write
def write_network_dir(net: Network, out, *, inputs=(), comments=()) -> list[Path]:
    """Write ``net`` as a directory of multilat's files, all or nothing
    (:func:`multilat.io.staging_dir`); ``comments``: lines above observations.csv's header."""
    from multilat.io import staging_dir

    with staging_dir(out, inputs=list(inputs)) as tmp:
        names = write_network_files(net, tmp, comments=comments)
    return [Path(out) / n for n in names]


def write_network_files(net: Network, directory, *, comments=()) -> list[str]:
    """points.csv, observations.csv and (for correlated blocks) covariances.csv of ``net`` into the
    existing ``directory``; the names written."""
    from multilat.io import write_text_atomic

    d = Path(directory)
    write_text_atomic(d / POINTS, _csv_text(*_point_rows(net.points)))
    header, rows, cov_rows = _observation_rows(net)
    lines = [f"# {c}" for c in comments]
    lines.append("# multilat general network (docs/general-network.md): SI units (m, rad), x east, y north, "
                 "z up, directions and angles counter-clockwise")
    write_text_atomic(d / OBSERVATIONS, _csv_text(header, rows, lines))
    names = [POINTS, OBSERVATIONS]
    if cov_rows:
        write_text_atomic(d / COVARIANCES, _csv_text(["block", "row", "col", "cov"], cov_rows))
        names.append(COVARIANCES)
    return names


def _csv_text(header, rows, comments=()) -> str:
    buf = _io.StringIO()
    for c in comments:
        buf.write(" ".join(str(c).split()) + "\n")
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(header)
    w.writerows(rows)
    return buf.getvalue()


def _num(v) -> str:
    return "" if not np.isfinite(v) else repr(float(v))


def _point_rows(pts: PointSet):
    header = ["point", "x_m", "y_m", "z_m"]
    fixed = (pts.status == FIXED).any()
    weighted = (pts.status == WEIGHTED).any()
    datum = bool(pts.constrained.any())
    header += (["fixed"] if fixed else []) + (list(_STD) if weighted else []) + (["datum"] if datum else [])
    rows = []
    for i, p in enumerate(pts.ids):
        r = [p, *(_num(v) for v in pts.xyz_m[i])]
        if fixed:
            r.append("".join(a for a, s in zip("xyz", pts.status[i]) if s == FIXED))
        if weighted:
            r += [_num(pts.sigma_m[i, a]) if pts.status[i, a] == WEIGHTED else "" for a in range(3)]
        if datum:
            r.append("true" if pts.constrained[i] else "false")
        rows.append(r)
    return header, rows


def _observation_rows(net: Network):
    """observations.csv's header and rows, covariances.csv's rows (the upper triangle's non-zero
    entries and every variance)."""
    cols: dict = {c: [] for c in _kind_columns()}
    cov_rows = []
    n = 0
    for b, block in enumerate(net.blocks):
        kind = KINDS[block.kind]
        m = block.n_rows
        own = kind.to_rows(block, net.points.ids)
        own.update(kind=[block.kind] * m, block=[str(b + 1)] * m, unit=[kind.UNIT] * m,
                   value=[repr(float(v)) for v in block.value], sigma=[repr(float(v)) for v in block.sigma])
        for c, lst in cols.items():
            lst += own.get(c, [""] * m)
        n += m
        if block.cov is not None:
            c = np.asarray(block.cov, float)
            if not np.array_equal(c, c.T):
                i, j = np.unravel_index(int(np.argmax(np.abs(c - c.T))), c.shape)
                raise MultilatError(f"{block.kind} block {b + 1}: its covariance is not symmetric (entry ({i + 1}, "
                                    f"{j + 1}) differs from ({j + 1}, {i + 1})): not written (make it symmetric, "
                                    "e.g. (C + C.T) / 2)")
            i, j = np.nonzero((np.triu(c) != 0) | np.eye(m, dtype=bool))
            cov_rows += [[str(b + 1), int(r) + 1, int(q) + 1, repr(float(c[r, q]))] for r, q in zip(i, j)]
    header = [c for c, v in cols.items() if c in ("kind", "block", "value", "sigma", "unit") or any(v)]
    rows = [[cols[c][k] for c in header] for k in range(n)]
    return header, rows, cov_rows


# ------------------------------------------------------------------------------------------- docs
def columns_markdown() -> str:
    """The documentation of the three files, generated from the kinds' ``COLUMNS`` (the section of
    ``docs/general-network.md`` between its ``generated`` markers; a test checks they agree)."""
    out = ["`points.csv`:", "", "| column | meaning |", "|---|---|"]
    out += [f"| `{c}` | {d} |" for c, d in POINT_COLUMNS]
    out += ["", "`observations.csv`, the columns every kind has:", "", "| column | meaning |", "|---|---|",
            "| `kind` | the observation kind (below; required) |",
            "| `block` | the block id: rows with one id form one block (one covariance in `covariances.csv`, one "
            "value of each option); empty: the rows of one kind (and options) form one block |",
            "| `value`, `sigma` | the observed value and its a-priori standard deviation, in `unit` (required "
            "columns) |",
            "| `unit` | the kind's unit, `m` or `rad` (required: a check) |"]
    for name, kind in KINDS.items():
        out += ["", f"`{name}` (unit `{kind.UNIT}`):", "", "| column | role | meaning |", "|---|---|---|"]
        for c in kind.COLUMNS:
            role = c.role + (", required" if c.required else "")
            if c.choices:
                role += ": " + " / ".join(f"`{x}`" for x in c.choices)
            out.append(f"| `{c.name}` | {role} | {c.doc} |")
    out += ["", "`covariances.csv` (only for correlated blocks):", "", "| column | meaning |", "|---|---|"]
    out += [f"| `{c}` | {d} |" for c, d in COVARIANCE_COLUMNS]
    return "\n".join(out) + "\n"
