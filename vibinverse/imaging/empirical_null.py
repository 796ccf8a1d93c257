"""The noise of a real recording, estimated from the recording itself, for the detection map.

The whitened power z of every pixel at every searched frequency is ~ Exp(1) on white noise that is
independent from pixel to pixel (`whitening.log_tail`). Real video is not: codec blocks, 8-bit
quantization, keyframe and lamp flicker, exposure steps and camera shake make z heavier-tailed
than Exp(1) and correlated over the frame. The detection map therefore takes, for each test, the
larger of the white-noise false-alarm probability and one measured on the recording:

* **Pixels** (which pixels carry a line): the pooled survival of z over every pixel and every
  searched frequency away from the candidate lines (`ZHistogram`, counts in `Z_EDGES`, gathered
  block by block in the first pass), interpolated log-linearly between the edges. Beyond the
  largest z seen off the lines it says nothing, and the white-noise tail stands alone.
* **Lines** (which frequencies carry a line anywhere in the frame): the largest z over the pixels
  at each frequency away from the candidates is a sample of the maximum of many (correlated,
  heavy-tailed) pixels. Its upper tail is taken as exponential above the sample's median u
  (peaks over a threshold with shape 0: the tail of a Gumbel law, which the maximum of many
  pixels follows, and of the exponential, which the maximum of a few dominant pixels follows),
  its scale beta the mean excess over u: P(max > z) = exp(-(z - u) / beta) / 2 for z > u. A
  frequency's false-alarm probability, corrected for the M frequencies searched, is
  1 - (1 - P)^M. (On white noise this is conservative: 1 % false alarms at a nominal 5 %; on
  pixels whose noise power varies log-normally by a factor 2, where the white-noise probability
  calls a line in every data set, it holds: 5 %; tests/vibinverse/imaging/test_empirical_null.py.)
  With fewer than `MIN_NULL_FREQUENCIES` frequencies away from the candidates (lines everywhere:
  a codec's comb of frame-pattern harmonics, a short clip), every frequency is the null, the
  candidates included: conservative, only lines that stand out of the others pass. With fewer
  than that many frequencies searched at all, the white-noise probability stands alone.
* **The frame** (is a line everywhere): the median of z over the pixels at each frequency. On
  noise it is ln 2 (the median of Exp(1)); a frequency where at least half the frame's pixels
  reach `FRAME_WIDE_MEDIAN` is a change of the whole picture (illumination, exposure, flicker,
  camera motion) rather than a structure's vibration, which moves the intensity only where the
  image has contrast.

The slow bins below the band (1-4 cycles per record) never enter these: their own null is
`slow_lines`'.

No equation of the paper is used here (the paper assumes white sensor noise, eq. 21).
"""

from __future__ import annotations

import dataclasses

import numpy as np

#: edges of the whitened-power histograms: 0, then 2^(k/3) from 1 to 2^20 ~ 1e6 (26 % steps; p-values
#: above P(Exp(1) > 1) = 0.37 are never small enough to matter)
Z_EDGES = np.r_[0.0, 2.0 ** (np.arange(61) / 3.0)]
#: the fewest frequencies away from the candidate lines that fit the tail of the maxima
MIN_NULL_FREQUENCIES = 12
#: bins on either side of a candidate line left out of the null (its sidelobes, a damped hump)
NULL_GUARD_BINS = 3
#: median whitened power over the frame from which a line is the whole picture's (noise: ln 2)
FRAME_WIDE_MEDIAN = 2.0


def z_counts(z: np.ndarray) -> np.ndarray:
    """Histogram counts (frequencies, len(Z_EDGES)) of whitened powers z (pixels, frequencies): row
    k counts frequency k's pixels in [Z_EDGES[j], Z_EDGES[j + 1]) (the last column: above the last
    edge)."""
    n_edges = Z_EDGES.size
    idx = np.searchsorted(Z_EDGES, z, side="right") - 1  # -1 never: z >= 0
    idx += np.arange(z.shape[1])[None, :] * n_edges
    return np.bincount(idx.ravel(), minlength=z.shape[1] * n_edges).reshape(z.shape[1], n_edges)


@dataclasses.dataclass(frozen=True)
class EmpiricalNull:
    """The recording's own null (module docstring), over the M searched frequencies."""

    n_searched: int
    survival: np.ndarray  # pooled P(z >= Z_EDGES[j]) off the candidate lines (len(Z_EDGES),)
    n_pooled: int  # the (pixel, frequency) pairs pooled
    frame_median: np.ndarray  # median z over the pixels at each searched frequency (M,), 0 below 1
    frame_fraction: np.ndarray  # fraction of the pixels with z >= FRAME_WIDE_MEDIAN at each frequency (M,)
    tail: tuple[float, float] | None  # (u, beta) of the maxima over the pixels' exponential tail; None: too few

    @classmethod
    def from_counts(cls, counts: np.ndarray, band_max: np.ndarray, candidates: np.ndarray) -> EmpiricalNull:
        """From the histograms (M, len(Z_EDGES)) and largest z (M,) of the searched frequencies, less
        those within NULL_GUARD_BINS of the `candidates` (indices into the M)."""
        m = counts.shape[0]
        off = np.ones(m, dtype=bool)
        for c in np.asarray(candidates, dtype=np.int64):
            off[max(0, c - NULL_GUARD_BINS) : c + NULL_GUARD_BINS + 1] = False
        if off.sum() < MIN_NULL_FREQUENCIES:  # lines everywhere (a codec's comb, a short clip): every
            off[:] = True  # frequency is the null, candidates included (conservative: they widen it)
        pooled = counts[off].sum(axis=0)
        n = int(pooled.sum())
        survival = np.cumsum(pooled[::-1])[::-1] / max(n, 1)
        tail = None
        if m >= MIN_NULL_FREQUENCIES:
            top = band_max[off]
            u = float(np.median(top))
            excess = top[top > u] - u
            if excess.size and excess.mean() > 0:
                tail = (u, float(excess.mean()))
        at = int(np.searchsorted(Z_EDGES, FRAME_WIDE_MEDIAN))  # an edge
        reach = counts[:, at:].sum(axis=1) / np.maximum(counts.sum(axis=1), 1)
        return cls(m, survival, n, _medians(counts), reach, tail)

    def log_tail(self, z: np.ndarray) -> np.ndarray:
        """ln of the pooled survival P(z' >= z) off the lines, log-linear between the edges; -inf
        beyond the largest z seen there (no evidence: the white-noise tail stands alone)."""
        z = np.asarray(z, dtype=np.float64)
        with np.errstate(divide="ignore"):
            log_s = np.r_[np.log(self.survival), -np.inf]
        j = np.clip(np.searchsorted(Z_EDGES, z, side="right") - 1, 0, Z_EDGES.size - 1)
        upper = Z_EDGES[np.minimum(j + 1, Z_EDGES.size - 1)]
        w = np.clip(
            np.divide(z - Z_EDGES[j], upper - Z_EDGES[j], out=np.zeros(z.shape), where=upper > Z_EDGES[j]), 0, 1
        )
        a, b = log_s[j], log_s[j + 1]
        # nothing seen above the bin's upper edge: P(z' >= z) <= P(z' >= its lower edge), kept (an upper
        # bound); nothing seen in the bin either (a = -inf): no evidence
        with np.errstate(invalid="ignore"):
            return np.where(np.isfinite(b), a + w * (b - a), a)

    def line_probability(self, zmax: np.ndarray) -> np.ndarray:
        """False-alarm probability of the largest z over the pixels at a frequency, corrected for the
        M frequencies searched (the maxima's exponential tail); 0 without a null (no evidence)."""
        zmax = np.asarray(zmax, dtype=np.float64)
        if self.tail is None:
            return np.zeros_like(zmax)
        u, beta = self.tail
        p = np.minimum(0.5 * np.exp(-(zmax - u) / beta), 1.0)
        with np.errstate(divide="ignore"):
            return -np.expm1(self.n_searched * np.log1p(-p))

    def frame_wide(self, k: int) -> bool:
        """Whether at least half the frame's pixels reach FRAME_WIDE_MEDIAN at searched frequency k."""
        return bool(self.frame_fraction[k] >= 0.5)


def _medians(counts: np.ndarray) -> np.ndarray:
    """Median per row of histograms (rows, len(Z_EDGES)), interpolated linearly inside its bin."""
    total = counts.sum(axis=1)
    cum = np.cumsum(counts, axis=1)
    half = 0.5 * total
    j = np.argmax(cum >= half[:, None], axis=1)
    below = np.where(j > 0, cum[np.arange(j.size), j - 1], 0)
    inside = counts[np.arange(j.size), j]
    frac = np.divide(half - below, inside, out=np.zeros(j.size), where=inside > 0)
    upper = Z_EDGES[np.minimum(j + 1, Z_EDGES.size - 1)]
    return np.where(total > 0, Z_EDGES[j] + frac * (upper - Z_EDGES[j]), 0.0)
