"""Figures written to disk: one PNG, atomically, and the figure closed whatever happens."""

from __future__ import annotations

import os


def save_png(fig, path: str | os.PathLike, *, tight: bool = True, dpi: int = 110) -> None:
    """Write the matplotlib figure ``fig`` to ``path`` whole or not at all, then close it."""
    import matplotlib.pyplot as plt

    from multilat.io import atomic_path

    try:
        with atomic_path(path) as tmp:
            fig.savefig(tmp, format="png", dpi=dpi, **({"bbox_inches": "tight"} if tight else {}))
    finally:
        plt.close(fig)
