"""The coordinate frame and the scale of an adjustment in words: computed once here, written to the
JSON as ``frame`` (:func:`multilat.network.adjust.distance.result.result_to_json`), and read from there by the
terminal summary (``multilat adjust``) and the HTML report's "Frame and datum" section.

Distances alone fix the shape and size of a network, not where it sits: under the default free datum
the coordinates are in the frame of the initial values (computed from the distances, or fitted onto
the given points), so e.g. floor targets may come out at z = -0.9 m. The words say so.

``frame`` is ``{"kind": "free" | "321" | "control", "axes": origin and axes in words,
"scale": where the scale comes from}``.
"""

from __future__ import annotations

__all__ = ["frame_words", "result_frame_words", "INVARIANT"]

INVARIANT = ("Coordinates depend on this choice; distances between points, offsets, scales and σ0 do not.")


def _list(v) -> str:
    return ", ".join(str(x) for x in v) if isinstance(v, (list, tuple)) else str(v)


def _axes(kind: str, points, initial: dict) -> str:
    init = initial.get("method", "not recorded")
    if kind == "free":
        from_points = init == "points" or "handedness" in initial
        ref = ("the given points' coordinates (points file)" if from_points
               else f"the initial values ({init}), not one chosen in the hall (z = 0 need not be the floor)"
               if init.startswith("distances") else f"the initial values ({init})")
        over = "all points" if points is None else f"the datum points {_list(points)}"
        return (f"the frame (origin and axes) is that of {ref}: the solution is fitted to them in least "
                f"squares over {over}, the covariance is the minimum-trace one over {over}. " + INVARIANT)
    if kind == "321":
        a, b, c = points
        return (f"{a} is the origin, {b} is on the +x axis, {c} is in the xy-plane (y > 0); those 6 "
                "coordinates have zero variance. " + INVARIANT)
    return ("the frame of the control coordinates (points file)"
            + ("" if points is None else f" of {_list(points)}")
            + ": hard control points are held fixed, weighted ones are observations with their σ "
              "(residuals under scale bars and control).")


def _scale(heads: dict, initial: dict, n_bars: int) -> str:
    scaled = [h for h, v in heads.items() if v.get("scale_estimated")]
    sd = initial.get("scale_datum")
    if scaled:
        return (f"scale factors estimated for heads {', '.join(scaled)}; the scale from "
                + (", ".join(f"{k}: {_list(v)}" for k, v in sd.items()) if isinstance(sd, dict)
                   else "the scale bars"))
    if n_bars:
        return "the distances and the scale bars (observations); no head has a scale factor"
    return "the distances (no head has a scale factor)"


def frame_words(datum, *, initial: dict | None = None, heads: dict | None = None, n_bars: int = 0) -> dict:
    """``{"kind", "axes", "scale"}`` for ``datum`` (a :class:`~multilat.network.model.datum.Datum` or its
    text), the adjustment's ``initial`` record, its ``heads`` (with ``scale_estimated``) and the number
    of scale bars used as observations."""
    from multilat.network.model.datum import parse_datum

    d = parse_datum(datum)
    initial = initial or {}
    return {"kind": d.kind, "axes": _axes(d.kind, d.points, initial),
            "scale": _scale(heads or {}, initial, n_bars)}


def result_frame_words(res) -> dict:
    """:func:`frame_words` of an :class:`~multilat.network.adjust.distance.result.AdjustmentResult`."""
    return frame_words(res.datum, initial=dict(res.initial), heads=res.heads(), n_bars=len(res.scale_bars))
