"""The paper's own loops and the reproduction of its Fig. 5 and Fig. 6."""

from hapstab.paper.loops import paper_hve, paper_peb

__all__ = ["paper_hve", "paper_peb"]
