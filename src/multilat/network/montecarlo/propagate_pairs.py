"""The interpoint distances a propagation reports: chosen pairs (``--pairs P1-P2,P3-P4`` or a CSV
file ``point_a,point_b``), the reference lengths' pairs, or by default every target pair of a small
network (consecutive ones of a large one); with the reference length of each pair when one is given."""

from __future__ import annotations

import numpy as np

from multilat.errors import MultilatError

__all__ = ["default_pairs", "pairs_and_refs", "parse_pairs"]


def default_pairs(target_ids, limit=20):
    """All target pairs for small networks, consecutive pairs otherwise."""
    if len(target_ids) <= limit:
        return tuple((a, b) for i, a in enumerate(target_ids) for b in target_ids[i + 1:])
    return tuple(zip(target_ids[:-1], target_ids[1:]))


def parse_pairs(text: str, *, option: str = "--pairs") -> tuple:
    """``"P1-P2,P3-P4"`` -> ``(("P1", "P2"), ("P3", "P4"))``; or the name of a CSV file with columns
    ``point_a,point_b`` (or ``target_a,target_b``: a reference-lengths file), one pair a row. An id
    with ``-`` in it goes in a file. One-line error naming the option (or FILE:LINE)."""
    from pathlib import Path

    p = Path(text)
    if p.suffix.lower() == ".csv" or p.is_file():
        return _pairs_file(p, option)
    out = []
    for item in (x.strip() for x in text.split(",")):
        parts = [q.strip() for q in item.split("-")]
        if len(parts) != 2 or not all(parts):
            raise MultilatError(f"{option}: expected P1-P2 (ids joined by one '-'; ids with '-' in a CSV file "
                                f"point_a,point_b), got {item!r}")
        out.append(tuple(parts))
    return tuple(out)


def _pairs_file(path, option):
    import csv

    if not path.is_file():
        raise MultilatError(f"{option}: {path}: no such file")
    with open(path, newline="", encoding="utf-8") as fh:
        rows = [(n, r) for n, r in enumerate(csv.reader(fh), 1) if r and not r[0].lstrip().startswith("#")]
    if not rows:
        raise MultilatError(f"{option}: {path}: no pairs")
    n0, head = rows[0]
    cols = [c.strip() for c in head]
    for a, b in (("point_a", "point_b"), ("target_a", "target_b")):
        if a in cols and b in cols:
            ia, ib = cols.index(a), cols.index(b)
            break
    else:
        raise MultilatError(f"{path}:{n0}: a pairs file needs the columns point_a,point_b (or target_a,target_b)")
    out = []
    for n, r in rows[1:]:
        if len(r) <= max(ia, ib) or not r[ia].strip() or not r[ib].strip():
            raise MultilatError(f"{path}:{n}: a pair needs two point ids")
        out.append((r[ia].strip(), r[ib].strip()))
    return tuple(out)


def pairs_and_refs(pairs, references, target_ids, station_ids, what: str = "interpoint distance"):
    refmap = {}
    if references is not None:
        if hasattr(references, "target_a"):
            refmap = {(a, b): float(L) for a, b, L in zip(references.target_a, references.target_b,
                                                          references.length_m)}
        else:
            refmap = {tuple(k): float(v) for k, v in dict(references).items()}
    if pairs is None:
        pairs = tuple(refmap) if refmap else default_pairs(target_ids)
    pairs = tuple((str(a), str(b)) for a, b in pairs)
    known = set(target_ids) | set(station_ids)
    for a, b in pairs:
        for p in (a, b):
            if p not in known:
                raise MultilatError(f"{what}: unknown point id {p!r}")
        if a == b:
            raise MultilatError(f"{what}: distance from {a!r} to itself")
    if len(set(pairs)) != len(pairs):
        dup = next(q for q in pairs if pairs.count(q) > 1)
        raise MultilatError(f"{what}: pair {dup[0]}-{dup[1]} given twice")
    ref = np.array([refmap.get((a, b), refmap.get((b, a), np.nan)) for a, b in pairs], float)
    return pairs, ref
