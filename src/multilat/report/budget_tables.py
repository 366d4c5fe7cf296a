"""The per-input table of the distance budget's report (``multilat budget --report``): the text cells
from :func:`multilat.budget_inputs.row_text`, the numbers as JSON-backed cells of the document's
``input_budget`` (nothing computed here)."""

from __future__ import annotations

from multilat.report.html import Num

__all__ = ["input_budget_table"]

HEADER = ("group", "input quantity", "distribution", "u(x)", "sensitivity c", "|c| u(x) (µm)",
          "Monte Carlo, this input alone (µm)", "share (µm)", "source (instrument file)")
_UM = 1e6


def _num_at(*path, doc, paths=True):
    from multilat.report.job_sections import ptr, resolve

    p = ptr(*path)
    return Num(resolve(doc, p), p if paths else "", _UM, 2)


def input_budget_table(sec, doc: dict, *, paths: bool = True) -> None:
    """Add the per-input table of ``doc["input_budget"]`` to the section ``sec``: every row, grouped,
    largest share first within each group, then the groups as sums of their rows. ``paths``: the
    cells name their place in ``doc`` (False where ``doc`` is no command's JSON, as in the demo)."""
    import functools

    from multilat.budget_inputs import row_text

    _num = functools.partial(_num_at, paths=paths)

    ib = doc["input_budget"]
    rows = []
    for g in ib["groups"]:
        mine = sorted((i for i, r in enumerate(ib["rows"]) if r["group"] == g),
                      key=lambda i: -abs(ib["rows"][i]["share_var_m2"]))
        for i in mine:
            r, x = ib["rows"][i], row_text(ib["rows"][i])
            rows.append((g, x["quantity"], x["distribution"], x["u"] if "u" in x else "-", x["sensitivity"],
                         _num("input_budget", "rows", i, "contribution_std_lin_m", doc=doc),
                         _num("input_budget", "rows", i, "contribution_std_mc_m", doc=doc),
                         _num("input_budget", "rows", i, "share_std_m", doc=doc), r.get("source") or "-"))
        label = g + ("" if g != "air" or ib["include_air"] else " (not in the combined)")
        rows.append((label, "sum of the rows: √(Σ share²)", "", "", "", "", "",
                     _num("input_budget", "groups", g, "error_rms_m", doc=doc),
                     _se_text(_num("input_budget", "groups", g, "error_rms_se_m", doc=doc))))
    rows.append(("combined", "the included rows; bias: square of the summed means", "", "", "", "", "",
                 _num("input_budget", "error_rms_m", doc=doc),
                 _se_text(_num("input_budget", "error_rms_se_m", doc=doc))))
    sec.table(HEADER, rows, caption=(
        f"Per input quantity ({ib['trials_per_distance']:,} trials per distance, k = 1). Sensitivity: partial "
        "derivative at the expectations (JCGM 100 §5.1); |c| u(x): first-order contribution; Monte Carlo alone: "
        "standard deviation of the group's error with only this input varying (JCGM 101, one at a time); share: "
        "the input's Shapley share of the group's variance, with a bias row per group (mean error), so that "
        "the squared shares of a group add up to its u². The misalignment (θ'', φ'') is one joint input "
        "(dependent, uncorrelated); all other inputs are independent."))


def _se_text(num: Num) -> str:
    return f"± {num.text()} µm (Monte Carlo standard error)"
