"""Slow lines: the first `LOW_BINS` Fourier frequencies (1 to 4 cycles per record), searched apart
from the others by `detection_map`.

A slow sway (a crane or a bridge filmed for a few seconds: two cycles in the clip) puts its power
where drift and illumination live. The whitened periodogram of the other frequencies cannot judge
it there: a pixel's floor extrapolated down to a few bins on the ln f axis is unreliable (a codec
pixel that holds its value for hundreds of frames drags the baseline's fit by orders of magnitude:
whitened powers of 40-120 at the slow bins of time-shuffled real video), and real video has slow
power in most pixels (codec rate control, exposure), unlike at the other frequencies. So a slow
bin is judged against the other pixels at the same bin, never pooled with the other frequencies:

1. Per pixel (first pass): its Fourier coefficients X_p(k) at the first LOW_BINS frequencies, its
   mean and line removed (`whitening.spectra_rows`); its two white floors, the median power of its
   first and of its last floor window / c, no baseline (`whitening.white_floor`); whether it
   reaches the ends of the integer range in some frame (clipped), and in how many frames its value
   changes. A pixel whose floor is below (ROUNDING x its mean)^2 has no power (constant to
   rounding: a fifth of a real video's pixels), nor has one whose value changes in fewer than
   MIN_CHANGES frames (a few events are no noise: two spikes in adjacent frames leave no power near
   Nyquist), nor have the frame's outermost pixels (`rim`: a camera's motion brings in there what
   the frame did not show).
2. The light (illumination, exposure, flicker): C(k), the median over the pixels (with power, not
   clipped: the bulk) of the real and of the imaginary parts of X_p(k), the frequency-domain
   counterpart of the per-frame median (a change of the whole picture moves every pixel one way, a
   sway moves the two sides of an edge in opposite ways). Each pixel has its own gain on it over
   the slow bins, b_p = Re sum_k X_p(k) C(k)* / sum_k |C(k)|^2 (a codec-held pixel has none), and
   z_p(k) = |X_p(k) - b_p C(k)|^2 / N / w_p is what remains over either floor w_p (0 without
   power). Measured on the simulated sways under a 3 % illumination random walk: without the
   light's gain, 1 and 4 of 20 are reported frame-wide instead of claimed (no false alarm either way).
3. The null at slow bin k, for each floor, from the bulk: its median m_k and its SLOW_TAIL_QUANTILE
   (0.8) quantile q_k (a sway on fewer than a fifth of the pixels moves neither). A pixel's power is a sum
   a g1^2 + b g2^2 of two squared normal parts of unequal weights (the line's removal; a red
   spectrum across the bin), whose far tail exp(-s / 2a) no pair of quantiles sees: so the tail is
   the gamma law through m_k and q_k with its shape at most 1/2 (`gamma_through`, GAMMA_SHAPE_CAP:
   chi-square with one degree of freedom through the median, heavier than any such sum; lower
   shapes where the bulk's pixels are of unequal levels), or an exponential shifted to the median,
   exp(-(s - m_k) / beta_k) / 2 with beta_k = (q_k - m_k) / ln 2.5 (a bulk narrow around a level),
   whichever is heavier, both scales raised by two standard errors of beta (1.89 beta / sqrt(n)
   for n pixels: the extrapolation to the frame's maximum magnifies its error); with the white-noise
   tail (`log_white_tail`: exact for white noise), the largest of the three. A pixel's p-value is
   the larger of its two floors': it must stand out of the bulk over both. Each floor alone failed
   on real noise: the first window's median is noisy for a drifting pixel (on 100 data sets of
   pixels drifting as random walks, test_detection_map's drift, slow lines in 3 at a nominal 1e-3;
   tails through both quantiles instead of the capped gamma: 6), the last window's is tiny for a
   codec pixel that changes only at keyframes (every 250 frames: a claimed slow line of 79 pixels in
   the static left part of the 64 Hz fork filmed at 500 fps); both together: none, and none at 0.1.
4. A slow line: a slow bin whose largest z over the P pixels (for each floor) has p-value p with
   1 - (1 - p)^{L P} < alpha (L slow bins searched: the slow search is a family of its own, as the
   other frequencies are). The slow bins that pass are one line (MERGE_GAP: they are at most 3
   bins apart), at the bin of largest power above the bulk's median summed over the pixels (a
   sway's fundamental spreads over more pixels than its harmonics); its frequency is that bin's,
   known to about a bin. Its pixels pass Benjamini-Hochberg at alpha, as for the other lines.

What the line is (`line_checks`), from `SlowSearch`: frame-wide when half the pixels carry the
power left, whitened by their floors as at the other frequencies (`Floor.whiten`); the camera's
when the frame's motion (`frame_model`: an affine displacement field moving the mean frame's
gradient, and its second-order terms, fitted robustly over the bulk) explains a tenth of its
pixels' power or more; local light when its pixels brighten and darken together
(`SlowSearch.light_share`: a region lit or shaded, a codec block's level stepping); clipped when
most of its pixels reach the ends of the range (a change of light moves them nonlinearly); and
scattered when its largest cluster has fewer than 32 pixels (`line_checks.SLOW_STRUCTURE_PIXELS`);
a drift when it is at one cycle in the record (`line_checks.OneCycle`: a sway's single cycle and a
region's slow drift look the same; the 64 Hz fork filmed at 1000 fps claimed one of 220 pixels).
A camera shaking by a random walk of 0.1 or 0.3 px made claimed slow lines in 2 and 1 of 40
simulated scenes without the camera and the size checks (the static edges respond nonlinearly),
none with either.

Limits, said in each slow line's note (`line_checks.Slow`): the statistics see slow power in a
region that the rest of the frame does not share. A sway makes it, and so does any slow motion of
a region: a shadow's edge or a cloud passing, a person walking, the filmed object moved. The null
is the bulk of the frame: pixels whose slow power differs from the bulk's for a reason of their
own (a region drifting more than the rest, codec blocks) pass as lines, reported as what the
checks say. The camera's motion is removed from no pixel's power (a codec holds pixels that do not
follow it, which its removal would light up): a shaking camera hides a sway there.

No equation of the paper is used here.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from vibinverse.imaging.empirical_null import FRAME_WIDE_MEDIAN
from vibinverse.imaging.whitening import Floor, FrequencyGrid, corrected, floor_constant

#: the bulk's upper quantile through which the exponential tail of a slow bin is fitted
SLOW_TAIL_QUANTILE = 0.8
#: the gamma law's shapes fitted: from a quarter (heavier than chi-square with 1 degree of freedom, 1/2)
#: to 50 (nearly a normal law)
GAMMA_SHAPES = (0.25, 50.0)
#: ... and used at most (module docstring, item 3): chi-square with 1 degree of freedom through the median
GAMMA_SHAPE_CAP = 0.5
#: the fewest pixels (with power, not clipped) for a slow search: fewer leave the bulk's tail unknown
MIN_SLOW_PIXELS = 64
#: a pixel whose white floor is below (ROUNDING x its mean)^2 is constant to rounding: no power
ROUNDING = 1e-10
#: a pixel whose value changes in fewer samples has too few events for its spectrum to be a noise's: a
#: codec holds it, two spikes in adjacent shuffled frames leave no power near Nyquist (its last floor
#: 0, its z 1e7 at a slow bin of time-shuffled real video)
MIN_CHANGES = 32
CHANGE_ROWS = 256  # `series_flags` compares this many samples at a time (a float64 diff of the batch would double it)
#: the frame model's robust fit: the share of pixels left out as outliers, and the rounds
TRIM, TRIM_ROUNDS = 0.2, 3
N_OFFSET = 1  # the columns of `frame_model` before the motion's: an offset
FIT_PIXELS = 4096  # the frame model is fitted to at most this many pixels of the bulk


def gamma_through(median: np.ndarray, upper: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(shape, scale) of the gamma laws whose median and SLOW_TAIL_QUANTILE quantile are `median` and
    `upper` (per bin), the shape within GAMMA_SHAPES (its ends when the ratio is beyond them); where
    that shape is above GAMMA_SHAPE_CAP, the law of shape GAMMA_SHAPE_CAP through the median alone
    (heavier above it); the scale 0 where the median is not positive (no evidence)."""
    from scipy import optimize, special

    u = SLOW_TAIL_QUANTILE

    def ratio(a: float) -> float:
        return float(special.gammaincinv(a, u) / special.gammaincinv(a, 0.5))

    shapes, scales = np.zeros(len(median)), np.zeros(len(median))
    lo, hi = GAMMA_SHAPES
    for k, (m, q) in enumerate(zip(median, upper)):
        if not (m > 0 and q > m):
            continue
        r = q / m
        a = lo if r >= ratio(lo) else hi if r <= ratio(hi) else optimize.brentq(lambda a: ratio(a) - r, lo, hi)
        a = min(a, GAMMA_SHAPE_CAP)
        shapes[k], scales[k] = a, m / special.gammaincinv(a, 0.5)
    return shapes, scales


def log_gamma_tail(x: np.ndarray, shape: float) -> np.ndarray:
    """ln P(X > x) for X ~ Gamma(shape, 1), by the regularized incomplete gamma function, and its
    asymptote (shape - 1) ln x - x - ln Gamma(shape) + ln(1 + (shape - 1) / x) where that underflows."""
    from scipy import special

    x = np.maximum(np.asarray(x, dtype=np.float64), 0.0)
    with np.errstate(divide="ignore"):
        direct = np.log(special.gammaincc(shape, x))
    far = (shape - 1.0) * np.log(np.maximum(x, 1.0)) - x - special.gammaln(shape)
    far += np.log1p((shape - 1.0) / np.maximum(x, 1.0))
    return np.where(np.isfinite(direct) & (direct > -600.0), direct, far)


def log_white_tail(z: np.ndarray, half_width: int) -> np.ndarray:
    """ln P(P / floor > z) on white noise for a power P apart from the 2h + 1 powers whose median /
    c is the floor (`whitening.white_floor`): the median is their (h+1)-th smallest, a sum of
    exponentials of rates 2h+1, 2h, ..., h+1, so P(z' > z) = prod_{i=0}^{h} (2h+1-i) / (2h+1-i + z/c)
    (`whitening.log_tail` is the same with the power one of the window's), by ln Gamma:
    prod_{a=h+1}^{2h+1} a / (a + x) = Gamma(2h+2) Gamma(h+1+x) / (Gamma(h+1) Gamma(2h+2+x))."""
    from scipy.special import gammaln

    h = int(half_width)
    x = np.maximum(np.asarray(z, dtype=np.float64), 0.0) / floor_constant(h)
    return np.minimum(gammaln(2 * h + 2) - gammaln(h + 1) + gammaln(h + 1 + x) - gammaln(2 * h + 2 + x), 0.0)


def has_power(white: np.ndarray, mean: np.ndarray) -> np.ndarray:
    """Whether each pixel has power above rounding: a finite white floor above (ROUNDING x mean)^2."""
    with np.errstate(invalid="ignore", over="ignore"):
        return np.isfinite(white) & (white > np.square(ROUNDING * np.nan_to_num(mean)))


def series_flags(y: np.ndarray, ends: tuple[float, float] | None) -> tuple[np.ndarray, np.ndarray]:
    """(clipped, changes) of each series of y (time, pixels): whether it reaches either end of the
    range `ends` (None: no range, nothing clipped) in some sample (missing samples skipped), and in
    how many samples its value changes."""
    changes = np.zeros(y.shape[1], dtype=np.int32)
    for start in range(0, y.shape[0] - 1, CHANGE_ROWS):  # in slices of time: no copy of the batch
        stop = min(start + CHANGE_ROWS, y.shape[0] - 1)
        changes += np.count_nonzero(y[start + 1 : stop + 1] != y[start:stop], axis=0).astype(np.int32)
    if ends is None:
        return np.zeros(y.shape[1], dtype=bool), changes
    return (np.fmin.reduce(y, axis=0) <= ends[0]) | (np.fmax.reduce(y, axis=0) >= ends[1]), changes


def rim(shape: tuple[int, int]) -> np.ndarray:
    """The frame's outermost pixels (pixels,), along each axis of 3 pixels or more: a camera's motion
    brings in there what the mean frame does not show, so they are not searched."""
    out = np.zeros(shape, dtype=bool)
    if shape[0] >= 3:
        out[[0, -1], :] = True
    if shape[1] >= 3:
        out[:, [0, -1]] = True
    return out.ravel()


def frame_model(mean_frame: np.ndarray, rows: np.ndarray | slice = slice(None)) -> np.ndarray:
    """The cross-pixel model of the camera's motion at one slow bin, (rows, 10), at the pixels `rows`
    (flat indices): an offset (N_OFFSET columns), then the mean frame's gradient moved by an affine
    displacement field (gx, gy, x gx, y gx, x gy, y gy: shake, rotation, zoom) and its second
    derivatives (gxx, gxy, gyy: a sharp edge's response to a motion of a fraction of a pixel), each
    column scaled to unit spread over the frame."""
    m = np.nan_to_num(np.asarray(mean_frame, dtype=np.float64))
    ny, nx = m.shape
    gy = np.gradient(m, axis=0) if ny > 1 else np.zeros(m.shape)
    gx = np.gradient(m, axis=1) if nx > 1 else np.zeros(m.shape)
    yy, xx = np.meshgrid(np.linspace(-1.0, 1.0, ny), np.linspace(-1.0, 1.0, nx), indexing="ij")
    gxx = np.gradient(gx, axis=1) if nx > 1 else np.zeros(m.shape)
    gyy = np.gradient(gy, axis=0) if ny > 1 else np.zeros(m.shape)
    gxy = np.gradient(gx, axis=0) if ny > 1 else np.zeros(m.shape)
    cols = [np.ones(m.shape), gx, gy, xx * gx, yy * gx, xx * gy, yy * gy, gxx, gxy, gyy]
    return np.stack([c.ravel()[rows] / (c.std() or 1.0) if k else c.ravel()[rows] for k, c in enumerate(cols)], axis=1)


def fit_frame_model(coef: np.ndarray, model: np.ndarray, weight: np.ndarray) -> np.ndarray:
    """The coefficients (bins, columns; complex) of the cross-pixel `model` (pixels, columns) fitted
    at each bin to the pixels' coefficients coef (pixels, bins; complex): weighted least squares,
    less the TRIM share of pixels with the largest weighted residuals, TRIM_ROUNDS times (a sway's
    pixels, a minority, fall out of the fit)."""
    out = np.zeros((coef.shape[1], model.shape[1]), dtype=np.complex128)
    a = model * weight[:, None]
    for k in range(coef.shape[1]):
        b = coef[:, k] * weight
        sel = np.ones(b.size, dtype=bool)
        for _ in range(TRIM_ROUNDS):
            out[k] = np.linalg.lstsq(a[sel], b[sel], rcond=None)[0]
            miss = np.abs(b - a @ out[k])
            sel = miss <= np.quantile(miss, 1.0 - TRIM)
    return out


@dataclasses.dataclass(frozen=True)
class BulkTail:
    """The bulk's tail at each searched slow bin (module docstring, item 3), for one floor."""

    median: np.ndarray  # (bins,) m_k
    scale: np.ndarray  # (bins,) beta_k of the shifted exponential (margin included)
    shape: np.ndarray  # (bins,) the gamma law's shape (at most GAMMA_SHAPE_CAP)
    gamma_scale: np.ndarray  # (bins,) ... and its scale (margin included; 0: no evidence)

    @classmethod
    def of(cls, z: np.ndarray) -> BulkTail:
        """From the bulk's z (pixels, bins)."""
        u = SLOW_TAIL_QUANTILE
        median = np.median(z, axis=0)
        upper = np.quantile(z, u, axis=0)
        margin = 1.0 + 2.0 * math.sqrt(u / (1.0 - u) - 1.0) / math.log(0.5 / (1.0 - u)) / math.sqrt(z.shape[0])
        shape, gamma_scale = gamma_through(median, upper)
        beta = np.maximum(upper - median, 0.0) / math.log(0.5 / (1.0 - u))
        return cls(median, beta * margin, shape, gamma_scale * margin)

    def log_p(self, z: np.ndarray, j: int, half_width: int) -> np.ndarray:
        """ln of the p-value of z at searched slow bin j: the largest of the white-noise tail and the
        two bulk tails (0 where the bulk has no spread: no evidence)."""
        z = np.asarray(z, dtype=np.float64)
        if not (self.scale[j] > 0 and self.gamma_scale[j] > 0):
            return np.zeros_like(z)
        shifted = np.minimum(math.log(0.5) - (z - self.median[j]) / self.scale[j], 0.0)
        gamma = log_gamma_tail(z / self.gamma_scale[j], float(self.shape[j]))
        return np.maximum(np.maximum(log_white_tail(z, half_width), shifted), gamma)


@dataclasses.dataclass(frozen=True)
class SlowSearch:
    """The slow bins' statistics over the frame (module docstring), at the grid's slow bins."""

    bins: np.ndarray  # the slow bins searched (indices into the grid)
    z: np.ndarray  # (pixels, bins): power left by the light / the first white floor; 0 without power
    z_last: np.ndarray  # (pixels, bins): ... / the last white floor
    tails: tuple[BulkTail, BulkTail]  # the bulk's, for z and z_last
    frame_median: np.ndarray  # (bins,) median over the pixels with power of the power left / its floor
    frame_fraction: np.ndarray  # (bins,) fraction of them at FRAME_WIDE_MEDIAN or more
    clipped: np.ndarray  # (pixels,) bool
    half_width: int  # h of the white floors' windows
    left: np.ndarray  # (pixels, bins): the coefficients left by the light, / sqrt(N first floor): |.|^2 = z
    mean_frame: np.ndarray  # (y, x)
    white: np.ndarray  # (pixels,): the first white floors (1 without power)
    motion: np.ndarray  # (bins, columns): the frame model (`frame_model`) fitted over the bulk, / sqrt(N)

    @classmethod
    def from_parts(
        cls,
        coef: np.ndarray,
        white: np.ndarray,
        mean_frame: np.ndarray,
        flags: tuple[np.ndarray, np.ndarray],
        floor: Floor,
        grid: FrequencyGrid,
    ) -> SlowSearch | None:
        """From every pixel's slow coefficients (pixels, LOW_BINS), white floors (pixels, 2: the first
        and the last window's), the mean frame (y, x), `series_flags` (pixels,) and floors; None when
        no slow bin is searched or fewer than MIN_SLOW_PIXELS pixels have power and are not clipped."""
        bins = grid.slow_bins
        clip, changes = flags
        power = has_power(white.min(axis=1), mean_frame.ravel()) & ~rim(mean_frame.shape) & (changes >= MIN_CHANGES)
        bulk = power & ~clip
        if bins.size == 0 or bulk.sum() < MIN_SLOW_PIXELS:
            return None
        # weights 1 / sqrt(white floor), the floor at least the bulk's median: pixels that hold their
        # value (codec) are quiet, not more telling of the light or the motion
        first = np.where(power, white[:, 0], 1.0)
        level = float(np.median(first[bulk]))
        weight = np.where(bulk, 1.0 / np.sqrt(np.maximum(first, level)), 0.0)
        # the light: each pixel's own gain on the frame's common mode (a codec-held pixel has none)
        common = np.median(coef[bulk].real, axis=0) + 1j * np.median(coef[bulk].imag, axis=0)
        norm = float(np.sum(np.square(np.abs(common))))
        gain = (coef @ np.conj(common)).real / norm if norm > 0 else np.zeros(coef.shape[0])
        n = grid.time.size
        left = coef[:, bins] - gain[:, None] * common[None, bins]
        left_power = np.square(np.abs(left)) / n
        z_last = np.where(power[:, None], left_power / np.where(power, white[:, 1], 1.0)[:, None], 0.0)
        left *= np.where(power, 1.0 / np.sqrt(n * first), 0.0)[:, None]
        z = np.square(np.abs(left))
        # the camera's motion, for the lines' classification only: subtracted, it would light up the
        # pixels that do not follow it (a codec holds a pixel's value for many frames). Fitted to at
        # most FIT_PIXELS of the bulk, evenly spread
        fit = np.flatnonzero(bulk)[:: max(1, -(-int(bulk.sum()) // FIT_PIXELS))]
        coef_fit = left[fit] * np.sqrt(n * first[fit])[:, None]  # the coefficients less the light
        motion = fit_frame_model(coef_fit, frame_model(mean_frame, fit), weight[fit]) / math.sqrt(n)
        whitened = floor.whiten(left_power, grid, bins)[power]
        return cls(
            bins,
            z,
            z_last,
            (BulkTail.of(z[bulk]), BulkTail.of(z_last[bulk])),
            np.median(whitened, axis=0),
            np.mean(whitened >= FRAME_WIDE_MEDIAN, axis=0),
            clip,
            grid.half_width,
            left,
            mean_frame,
            first,
            motion,
        )

    def log_p(self, j: int) -> np.ndarray:
        """ln of each pixel's p-value at searched slow bin j (`bins` index): the larger of its two
        floors' (a line must stand out of the bulk by both)."""
        first, last = self.tails
        return np.maximum(
            first.log_p(self.z[:, j], j, self.half_width), last.log_p(self.z_last[:, j], j, self.half_width)
        )

    def light_share(self, j: int, pixels: np.ndarray) -> float:
        """The share of the power left at `pixels` (a mask; 0 for fewer than 3) at searched slow bin j
        that a change of their light explains, a + b m_p (complex a, b; m the mean frame): a region
        that brightens or darkens together, where a moving edge changes its two sides in opposite ways."""
        x = self.left[pixels, j]
        if x.size < 3:
            return 0.0
        m = np.nan_to_num(self.mean_frame.ravel())
        a = np.stack([np.ones(x.size), (m[pixels] - m.mean()) / (m.std() or 1.0)], axis=1)
        fitted = a @ np.linalg.lstsq(a, x, rcond=None)[0]
        total = float(np.sum(np.square(np.abs(x))))
        return 1.0 - float(np.sum(np.square(np.abs(x - fitted)))) / total if total > 0 else 0.0

    def motion_share(self, j: int, pixels: np.ndarray) -> float:
        """The share of the power of `pixels` (a mask) at searched slow bin j that the frame's motion
        model explains (0 for no pixel)."""
        seen = float(self.z[pixels, j].sum())
        if seen <= 0:
            return 0.0
        moved = frame_model(self.mean_frame, np.flatnonzero(pixels))[:, N_OFFSET:] @ self.motion[j, N_OFFSET:]
        return float(np.sum(np.square(np.abs(moved)) / self.white[pixels])) / seen

    @property
    def n_pixels(self) -> int:
        return self.z.shape[0]

    def line_probability(self) -> np.ndarray:
        """The false-alarm probability (bins,) of each slow bin's largest z over the pixels, for each
        floor, the larger of the two, corrected for the pixels and the slow bins searched."""
        first, last = self.tails
        log_p = [
            max(
                float(first.log_p(self.z[:, j].max(), j, self.half_width)),
                float(last.log_p(self.z_last[:, j].max(), j, self.half_width)),
            )
            for j in range(self.bins.size)
        ]
        return corrected(np.array(log_p), self.bins.size * self.n_pixels)

    def frame_wide(self, j: int) -> bool:
        """Whether half the pixels with power carry the power left at searched slow bin j."""
        return bool(self.frame_fraction[j] >= 0.5)
