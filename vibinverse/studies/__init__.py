"""Reproductions of the paper's figures: `vibinverse study NAME [-o DIR]`.

Each study writes DIR/NAME.png, DIR/NAME.csv (the curve) and DIR/NAME.json (key numbers), and
returns a one-line summary. `quick=True` runs a reduced version (tests). Names are the paper's
figure numbers; two captions in the paper are wrong (the amplitude study, Fig. 10, is captioned
"Figure 1"; the text calls it Figure 14), so the help text names each by content.
"""

from vibinverse.studies.brewster import fig11
from vibinverse.studies.fig2 import fig2
from vibinverse.studies.fig4 import fig4
from vibinverse.studies.fig6 import fig6
from vibinverse.studies.frame_views import fig13
from vibinverse.studies.ground_sweeps import fig14, fig15
from vibinverse.studies.roof_views import fig8, fig9, fig10

STUDIES = {
    "fig2": (fig2, "elastic glass pane: displacement and gradient (eq. 10)"),
    "fig4": (fig4, "building frame: impulse-train and frequency response"),
    "fig6": (fig6, "ground Rayleigh waves: radial slices over half a period"),
    "fig8": (fig8, "elastic roof, centered footprint: sensitivity vs view offset"),
    "fig9": (fig9, "elastic roof, quadrant footprint: sensitivity vs view offset"),
    "fig10": (fig10, "elastic roof, quadrant: sensitivity vs vibration amplitude"),
    "fig11": (fig11, "glass pane behind a p-polarizer: sensitivity vs incidence near Brewster"),
    "fig13": (fig13, "roof on a resonant frame: sensitivity vs view offset, spectral lines"),
    "fig14": (fig14, "ground: sensitivity vs sun inclination"),
    "fig15": (fig15, "ground: sensitivity vs footprint width"),
}

__all__ = ["STUDIES"]
