"""The per-input table of the distance budget's report (``multilat budget --report``): cells from
:func:`multilat.budget_inputs.row_text` (the numbers are those of the JSON document, nothing computed
here)."""

from __future__ import annotations

__all__ = ["input_budget_table"]

HEADER = ("group", "input quantity", "distribution", "u(x)", "sensitivity c", "|c| u(x) (µm)",
          "Monte Carlo, this input alone (µm)", "share (µm)", "source (instrument file)")


def input_budget_table(sec, ib: dict) -> None:
    """Add the per-input table of ``ib`` (the document's ``input_budget``) to the section ``sec``:
    every row, grouped, largest share first within each group, then the groups as sums of their rows."""
    from multilat.budget_inputs import row_text

    rows = []
    for g, tot in ib["groups"].items():
        mine = sorted((r for r in ib["rows"] if r["group"] == g), key=lambda r: -abs(r["share_var_m2"]))
        for r in mine:
            x = row_text(r)
            rows.append((g, x["quantity"], x["distribution"], x.get("u", "-"), x["sensitivity"], x["u_gum"],
                         x["u_mc"], x["u_share"], r.get("source") or "-"))
        label = g + ("" if g != "air" or ib["include_air"] else " (not in the combined)")
        rows.append((label, "sum of the rows: √(Σ share²)", "", "", "", "", "",
                     f"{tot['error_rms_m'] * 1e6:.2f} ± {tot['error_rms_se_m'] * 1e6:.2f}", ""))
    rows.append(("combined", "sum of the included rows, bias of the summed means", "", "", "", "", "",
                 f"{ib['error_rms_m'] * 1e6:.2f} ± {ib['error_rms_se_m'] * 1e6:.2f}", ""))
    sec.table(HEADER, rows, caption=(
        f"Per input quantity ({ib['trials_per_distance']:,} trials per distance, k = 1). Sensitivity: partial "
        "derivative at the expectations (JCGM 100 §5.1); |c| u(x): first-order contribution; Monte Carlo alone: "
        "standard deviation of the group's error with only this input varying (JCGM 101, one at a time); share: "
        "the input's Shapley share of the group's variance (± its Monte Carlo standard error in the sums), with a "
        "bias row per group, so that the squared shares of a group add up to its u². The misalignment "
        "(θ'', φ'') is one joint input (dependent, uncorrelated); all other inputs are independent."))
