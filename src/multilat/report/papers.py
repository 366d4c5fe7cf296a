"""The papers the project implements, cited in full (reports, demo). The author lists are those
printed on the papers (the extraction of the LBB paper kept only its first author: "J. Suzanne
Canning et al.", as printed in its running head)."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Paper:
    key: str
    authors: str
    title: str
    journal: str
    volume: str
    year: int
    pages: str
    doi: str = ""

    def short(self) -> str:
        """``Guillory et al. 2020``."""
        first = self.authors.split(",")[0].replace(" et al.", "").split()[-1]
        return f"{first} et al. {self.year}"

    def citation(self) -> str:
        doi = f", doi:{self.doi}" if self.doi else ""
        return (f"{self.authors}, “{self.title}”, {self.journal} {self.volume} ({self.year}) "
                f"{self.pages}{doi}")


GUILLORY_2020 = Paper("seed 000", "J. Guillory, D. Truong, J.-P. Wallerand",
                      "Uncertainty assessment of a prototype of multilateration coordinate measurement system",
                      "Precision Engineering", "66", 2020, "496–506", "10.1016/j.precisioneng.2020.08.002")
CANNING_2007 = Paper("seed 003", "J. Suzanne Canning et al.",
                     "Coordinate metrology uncertainty using parallel kinematic techniques",
                     "International Journal of Machine Tools & Manufacture", "47", 2007, "658–665")
PAPERS = (GUILLORY_2020, CANNING_2007)


def cite(text: str) -> str:
    """Replace the project's shorthand ``seed 000`` / ``seed 003`` by ``Guillory et al. 2020 [1]``."""
    for i, p in enumerate(PAPERS, 1):
        text = text.replace(p.key, f"{p.short()} [{i}]")
    return text
