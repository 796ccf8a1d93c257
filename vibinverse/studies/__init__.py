"""Reproductions of the paper's figures: `vibinverse study NAME [-o DIR]`.

Each study writes DIR/NAME.png, DIR/NAME.csv (the curve) and DIR/NAME.json (key numbers), and
returns a one-line summary.
"""

from vibinverse.studies.fig4 import fig4

STUDIES = {"fig4": (fig4, "building-frame impulse-train and frequency response (paper Fig. 4)")}

__all__ = ["STUDIES"]
