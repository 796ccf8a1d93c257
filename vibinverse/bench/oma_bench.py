"""`vibinverse bench --oma`: multi-channel operational modal analysis (OMA) on simulated shear
buildings with known modes, ours against pyOMA2's SSI-cov, FDD and EFDD.

The cases (`OMA_CASES`) are shear buildings of 3-8 storeys (`forward.motion.shear_building`: exact
zero-order-hold modal superposition, independent floor forces, white or coloured), 0.5-15 Hz,
1-2 % damping, 2-12 channels, 10 min to 2 h at 20-200 Hz; close_pair has two lateral directions
whose first modes are 2 % apart, measured on shared channels (x, y and one sensor at 45 degrees);
drift_velocity adds a random walk as large as the signal. `quick` runs three of them (QUICK_CASES)
on shorter records.

Every method is a callable `(Channels, hints) -> list[dict]` with the hints `{"modes": the true
mode count, "band": (lo, hi) Hz, the case's analysis band}` and one dict per identified mode:
`frequency` (Hz), `damping_ratio` (None where the method has none), `shape` (1-D over the
channels) and, where the method gives them, 90 % `frequency_interval`, `damping_ratio_interval`
((lo, hi)) and `shape_interval` ((channels, 2)). Ours enters as such a callable (`run(ours=...)`).

The peers (pyOMA2 as a user would run it; each gets the mode count and the band, never the true
frequencies):

- every peer: linear trend removed (`SingleSetup.detrend_data`), decimated by FIR (zero phase,
  `SingleSetup.decimate_data`) to the lowest integer fraction of the rate that stays >= 2.5 x the
  band's upper edge;
- `spectral_peaks`: the first singular value of the spectral matrix (pyOMA2 `FDD`, Welch with a
  Hann window, 50 % overlap, segments of 2^round(log2(N / 16)) samples); its K most prominent peaks
  (prominence of log10 S1) inside the band, at least 2 bins apart;
- fdd: pyOMA2 `FDD.mpe` at those peaks (DF = 2 bins): frequency and shape, no damping;
- efdd: pyOMA2 `EFDD.mpe` mode by mode at those peaks (DF1 = 2 bins, DF2 = min(1 Hz, 0.3 f),
  MAClim 0.85, npmax 20, halved down to 5 where the bell's correlation has too few crossings).
  pyOMA2 1.4.3 builds the SDOF bell from `SD_svalsvec`, which returns the square roots of the
  spectral matrix's singular values: the bell is ~|H|, not |H|^2, its correlation decays faster than
  the mode's and the damping ratios come out 2-2.5x the true ones (relative errors 1.1-1.5 here);
  the bench runs EFDD as pyOMA2 ships it;
- ssi-cov: pyOMA2 `SSI(method="cov")`, references the 4 channels of largest sd (all where there
  are <= 4), ordmax = clip(4 K, 24, 60), block rows br = max(one period of the lowest spectral
  peak in samples, ordmax / references + 1, 10), capped so that the future block Hankel rows take
  <= 600 MB; pyOMA2's hard criteria (damping < 0.2, MPC > 0.5, MPD < 0.5, CoV < 0.2) and soft
  criteria (frequency 5 %, damping 10 %, 1 - MAC 5 % between successive orders) label the stable
  poles; the stable poles in the band are clustered (average linkage on |df| / f + 1 - MAC, cut at
  0.1), the K clusters present in the most model orders are the modes, each reported by its pole
  nearest the cluster's median frequency; calc_unc=True (pyOMA2's first-order propagation of the
  Hankel matrix's covariance over 50 blocks, Doehler & Mevel 2013): that pole's standard deviations
  give 90 % normal intervals f +- 1.645 sd, zeta +- 1.645 sd.

Every method runs on one BLAS thread (threadpoolctl), its wall time measured around the call; the
peers' imports are done before the first timed call (ours' are not: import them beforehand).

Shapes are compared after scaling to unit norm with the largest-magnitude component positive (the
real part of a complex shape, normalized first by its largest component).

Scores (`score`) per case, method and data set: true and identified modes matched by Hungarian
assignment on the relative frequency difference, a match counting within 10 %; per matched mode the
frequency's relative error, the damping ratio's absolute and relative error, the MAC with the true
shape, whether the 90 % intervals hold the truth (f, zeta, and each shape component, the shape's
interval scaled with the shape to unit norm); the close pair is resolved when both its modes
are matched and each estimate lies nearer its own true frequency than its partner's; wall time.
"""

from __future__ import annotations

import contextlib
import logging
import math
import time
import zlib
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from forward.motion.shear_building import (
    ShearBuilding,
    TwoWayShearBuilding,
    rayleigh_damping_ratios,
    simulate,
    unit_shapes,
)
from vibinverse.bench.robustness_fit import quiet
from vibinverse.io.channels import Channels

LOG = logging.getLogger(__name__).info

MATCH_TOL = 0.10  # an identified mode matches a true one within 10 % of its frequency
Z90 = 1.6448536269514722  # a 90 % normal interval is +- Z90 sd
UNITS = {"acceleration": "m/s^2", "velocity": "m/s", "displacement": "m"}
QUICK_CASES = ("three_storey", "close_pair", "two_channels")

Method = Callable[[Channels, dict], list[dict]]


# ------------------------------------------------------------------ the cases


def _three_storey() -> ShearBuilding:
    return ShearBuilding.with_first_frequency(3, 3.7, 0.015)


def _close_pair() -> TwoWayShearBuilding:
    # x uniform, y stiff below and soft above: the first modes 2 % apart, the others >= 20 % from any
    x = ShearBuilding.with_first_frequency(4, 1.50, 0.010)
    y = ShearBuilding.with_first_frequency(4, 1.53, 0.012, stiffness_profile=[1.0, 1.0, 0.3, 0.18])
    return TwoWayShearBuilding(x, y)


def _two_channels() -> ShearBuilding:
    freqs = ShearBuilding.with_first_frequency(4, 2.0, 0.01).frequencies
    return ShearBuilding.with_first_frequency(
        4, 2.0, rayleigh_damping_ratios(freqs, (freqs[0], 0.01), (freqs[-1], 0.02))
    )


def _five_storey() -> ShearBuilding:
    profile = [1.0, 0.9, 0.8, 0.7, 0.6]
    freqs = ShearBuilding.with_first_frequency(5, 1.2, 0.01, stiffness_profile=profile).frequencies
    zeta = rayleigh_damping_ratios(freqs, (freqs[0], 0.01), (freqs[-1], 0.02))
    return ShearBuilding.with_first_frequency(5, 1.2, zeta, stiffness_profile=profile)


def _six_storey() -> ShearBuilding:
    return ShearBuilding.with_first_frequency(6, 1.0, 0.015)


def _eight_storey() -> ShearBuilding:
    return ShearBuilding.with_first_frequency(8, 0.8, 0.012)


def _tall_two_way() -> TwoWayShearBuilding:
    return TwoWayShearBuilding(
        ShearBuilding.with_first_frequency(6, 0.5, 0.010), ShearBuilding.with_first_frequency(6, 0.95, 0.015)
    )


@dataclass(frozen=True)
class OMACase:
    """A simulated OMA data set: the building (a builder), the measured channels (storeys, or
    (storey, angle in plan in degrees)), the quantity, rate (Hz), record length (s; `quick_duration`
    with `quick`, None when the case is not in the quick set), forcing ("white", "coloured" with its
    corner in Hz), sensor noise and drift (fractions of each channel's response sd), the analysis
    band an analyst would choose (Hz; a hint to every method), and the indices (in ascending true
    frequency) of a close pair of modes, if any."""

    name: str
    what: str
    building: Callable[[], ShearBuilding | TwoWayShearBuilding]
    channels: tuple
    fs: float
    duration: float
    band: tuple[float, float]
    quick_duration: float | None = None
    quantity: str = "acceleration"
    forcing: str = "white"
    forcing_corner: float = 2.0
    noise_rms: float = 0.05
    drift: float = 0.0
    close_pair: tuple[int, int] | None = None

    def span(self, quick: bool = False) -> float:
        return float(self.quick_duration if quick and self.quick_duration else self.duration)

    def seed(self, k: int) -> int:
        """The k-th data set's seed: fixed per case name, whatever the order of the cases."""
        return zlib.crc32(self.name.encode()) % 100_000 * 1000 + int(k)

    def frequencies(self) -> np.ndarray:
        return self.building().modal().frequencies

    def simulate(self, k: int = 0, quick: bool = False) -> tuple[Channels, dict]:
        """(the k-th data set as Channels, its truth: `forward.motion.shear_building.simulate`'s)."""
        t, y, truth = simulate(
            self.building(),
            self.fs,
            self.span(quick),
            self.channels,
            quantity=self.quantity,
            forcing=self.forcing,
            noise_rms=self.noise_rms,
            drift=self.drift,
            seed=self.seed(k),
            forcing_corner=self.forcing_corner,
        )
        names = truth["channels"]
        unit = UNITS[self.quantity]
        ch = Channels(t, y, names, (unit,) * len(names), f"oma bench {self.name} seed {self.seed(k)}")
        return ch, truth

    def hints(self) -> dict:
        return {"modes": len(self.frequencies()), "band": tuple(self.band)}


_BIAXIAL_SIX = tuple((s, a) for s in range(1, 7) for a in (0.0, 90.0))

OMA_CASES: dict[str, OMACase] = {
    c.name: c
    for c in (
        OMACase(
            "three_storey",
            "3 storeys, 3.7-15.0 Hz, every floor, white forcing, 10 % noise",
            _three_storey,
            (1, 2, 3),
            fs=100.0,
            duration=600.0,
            quick_duration=300.0,
            band=(1.0, 20.0),
            noise_rms=0.10,
        ),
        OMACase(
            "close_pair",
            "two directions of 4 storeys, first modes 1.50 and 1.53 Hz (2 %), x, y and 45-degree sensors",
            _close_pair,
            ((2, 0.0), (4, 0.0), (2, 90.0), (4, 90.0), (3, 45.0)),
            fs=25.0,
            duration=1800.0,
            quick_duration=600.0,
            band=(0.5, 12.0),
            close_pair=(0, 1),
        ),
        OMACase(
            "two_channels",
            "4 storeys, 2.0-10.8 Hz, two channels, coloured forcing (5 Hz corner), Rayleigh damping 1-2 %",
            _two_channels,
            (2, 4),
            fs=50.0,
            duration=600.0,
            quick_duration=300.0,
            band=(0.5, 15.0),
            forcing="coloured",
            forcing_corner=5.0,
            noise_rms=0.10,
        ),
        OMACase(
            "five_storey",
            "5 storeys tapering, 1.2-7.8 Hz, every floor, coloured forcing (2 Hz corner), Rayleigh 1-2 %",
            _five_storey,
            (1, 2, 3, 4, 5),
            fs=40.0,
            duration=1200.0,
            band=(0.3, 10.0),
            forcing="coloured",
            forcing_corner=2.0,
            noise_rms=0.10,
        ),
        OMACase(
            "drift_velocity",
            "6 storeys, 1.0-8.1 Hz, velocity at 3 floors, 200 Hz, a random-walk drift as large as the signal",
            _six_storey,
            (2, 4, 6),
            fs=200.0,
            duration=600.0,
            band=(0.3, 10.0),
            quantity="velocity",
            drift=1.0,
        ),
        OMACase(
            "eight_storey",
            "8 storeys, 0.8-8.5 Hz, every floor, 1 h, coloured forcing (3 Hz corner)",
            _eight_storey,
            tuple(range(1, 9)),
            fs=50.0,
            duration=3600.0,
            band=(0.2, 12.0),
            forcing="coloured",
            forcing_corner=3.0,
            noise_rms=0.10,
        ),
        OMACase(
            "tall_two_way",
            "two directions of 6 storeys, 0.5-7.7 Hz, 12 channels (x and y at every floor), 2 h",
            _tall_two_way,
            _BIAXIAL_SIX,
            fs=20.0,
            duration=7200.0,
            band=(0.2, 10.0),
        ),
    )
}


# ------------------------------------------------------------------ the peers (pyOMA2)


def _setup(ch: Channels, band: tuple[float, float]):
    """A pyOMA2 SingleSetup of the channels, linear trend removed, decimated (FIR, zero phase) to
    the lowest integer fraction of the rate >= 2.5 x the band's upper edge."""
    from pyoma2.setup import SingleSetup

    setup = SingleSetup(np.array(ch.values, dtype=float), fs=ch.fs)
    setup.detrend_data(type="linear")
    q = int(ch.fs // (2.5 * band[1]))
    if q > 1:
        setup.decimate_data(q, ftype="fir", zero_phase=True)
    return setup


def _nxseg(n: int, segments: int = 16) -> int:
    """Welch segment length: the power of 2 nearest N / segments (>= 64)."""
    return int(2 ** max(6, round(math.log2(max(n, 2) / segments))))


def spectral_peaks(freq: np.ndarray, s1: np.ndarray, k: int, band: tuple[float, float]) -> list[float]:
    """The `k` most prominent local maxima of log10(s1) (the first singular value of the spectral
    matrix) strictly inside `band`, at least 2 bins apart, in ascending frequency."""
    from scipy.signal import find_peaks

    df = float(freq[1] - freq[0])
    logs = np.log10(np.maximum(np.asarray(s1, float), 1e-300))
    idx, props = find_peaks(logs, prominence=0.0, distance=2)
    inside = (freq[idx] > max(band[0], 2 * df)) & (freq[idx] < band[1])
    idx, prom = idx[inside], props["prominences"][inside]
    top = idx[np.argsort(prom)[::-1][:k]]
    return sorted(float(freq[i]) for i in top)


def _real_shape(phi: np.ndarray) -> np.ndarray:
    """A (possibly complex) shape as a real unit vector: divided by its largest-magnitude component
    (removing the common phase), the real part, unit norm, largest component positive."""
    phi = np.asarray(phi).ravel()
    if np.iscomplexobj(phi):
        i = int(np.nanargmax(np.abs(phi)))
        phi = np.real(phi / phi[i]) if abs(phi[i]) > 0 else np.real(phi)
    return unit_shapes(np.asarray(phi, float)[:, None])[:, 0]


@dataclass
class FDDPeer:
    """pyOMA2's FDD (module docstring): frequencies and shapes at the first singular value's K most
    prominent peaks in the band; no damping, no intervals."""

    name: str = "fdd"
    segments: int = 16
    last: dict = field(default_factory=dict)

    def spectrum(self, ch: Channels, hints: dict):
        """(setup, the run FDD algorithm, the peaks)."""
        from pyoma2.algorithms import FDD

        band = tuple(hints.get("band") or (0.0, 0.5 * ch.fs))
        setup = _setup(ch, band)
        nxseg = _nxseg(setup.data.shape[0], self.segments)
        alg = FDD(name="fdd", nxseg=nxseg, method_SD="per", pov=0.5)
        setup.add_algorithms(alg)
        setup.run_by_name("fdd")
        res = alg.result
        k = int(hints.get("modes") or 1)
        peaks = spectral_peaks(res.freq, res.S_val[0, 0, :], k, band)
        self.last = {"fs": float(setup.fs), "nxseg": nxseg, "df": float(res.freq[1] - res.freq[0]), "peaks": peaks}
        return setup, alg, peaks

    def __call__(self, ch: Channels, hints: dict) -> list[dict]:
        _, alg, peaks = self.spectrum(ch, hints)
        if not peaks:
            return []
        alg.mpe(sel_freq=peaks, DF=2.0 * self.last["df"])
        fn, phi = np.atleast_1d(alg.result.Fn), np.atleast_2d(alg.result.Phi)
        return [
            {"frequency": float(f), "damping_ratio": None, "shape": _real_shape(phi[:, i])} for i, f in enumerate(fn)
        ]


@dataclass
class EFDDPeer(FDDPeer):
    """pyOMA2's EFDD (module docstring), mode by mode at the FDD peaks: a mode whose bell gives too
    few correlation crossings is retried with npmax halved (20, 10, 5), then dropped."""

    name: str = "efdd"

    def __call__(self, ch: Channels, hints: dict) -> list[dict]:
        from pyoma2.algorithms import EFDD

        band = tuple(hints.get("band") or (0.0, 0.5 * ch.fs))
        setup = _setup(ch, band)
        nxseg = _nxseg(setup.data.shape[0], self.segments)
        alg = EFDD(name="efdd", nxseg=nxseg, method_SD="per", pov=0.5)
        setup.add_algorithms(alg)
        setup.run_by_name("efdd")
        res = alg.result
        df = float(res.freq[1] - res.freq[0])
        peaks = spectral_peaks(res.freq, res.S_val[0, 0, :], int(hints.get("modes") or 1), band)
        out, dropped = [], []
        for f in peaks:
            for npmax in (20, 10, 5):
                try:
                    alg.mpe(sel_freq=[f], DF1=2.0 * df, DF2=min(1.0, 0.3 * f), cm=1, MAClim=0.85, sppk=3, npmax=npmax)
                except (ValueError, RuntimeError, IndexError):  # too few crossings; curve_fit failed
                    continue
                fn, xi = float(np.ravel(alg.result.Fn)[0]), float(np.ravel(alg.result.Xi)[0])
                out.append(
                    {"frequency": fn, "damping_ratio": xi, "shape": _real_shape(np.asarray(alg.result.Phi)[:, 0])}
                )
                break
            else:
                dropped.append(f)
        self.last = {"fs": float(setup.fs), "nxseg": nxseg, "df": df, "peaks": peaks, "dropped": dropped}
        return out


@dataclass
class SSICovPeer:
    """pyOMA2's SSI-cov with uncertainty (module docstring)."""

    name: str = "ssi-cov"
    max_refs: int = 4
    calc_unc: bool = True
    n_blocks: int = 50
    cluster_cut: float = 0.1
    hankel_bytes: float = 6e8
    last: dict = field(default_factory=dict)

    def __call__(self, ch: Channels, hints: dict) -> list[dict]:
        from pyoma2.algorithms import SSI

        band = tuple(hints.get("band") or (0.0, 0.5 * ch.fs))
        k = int(hints.get("modes") or 1)
        fdd = FDDPeer()
        setup, _, peaks = fdd.spectrum(ch, hints)  # the lowest spectral peak sets the block rows
        fs, n, nch = float(setup.fs), setup.data.shape[0], setup.data.shape[1]
        refs = None
        if nch > self.max_refs:
            refs = sorted(int(i) for i in np.argsort(np.std(setup.data, axis=0))[::-1][: self.max_refs])
        r = nch if refs is None else len(refs)
        ordmax = int(np.clip(4 * k, 24, 60))
        f_low = min(peaks) if peaks else max(band[0], 10.0 / (n / fs))
        br = max(math.ceil(fs / f_low), math.ceil((ordmax + 1) / r) + 1, 10)
        cap = max(10, int(self.hankel_bytes / (8.0 * nch * n)))
        capped = br > cap
        br = min(br, cap)
        ordmax = min(ordmax, br * r - 1)
        hc = {"xi_max": 0.2, "mpc_lim": 0.5, "mpd_lim": 0.5, "CoV_max": 0.2 if self.calc_unc else None}
        sc = {"err_fn": 0.05, "err_xi": 0.1, "err_phi": 0.05}
        alg = SSI(
            name="ssi",
            method="cov",
            br=br,
            ordmax=ordmax,
            ref_ind=refs,
            calc_unc=self.calc_unc,
            nb=self.n_blocks,
            hc=hc,
            sc=sc,
        )
        setup.add_algorithms(alg)
        setup.run_by_name("ssi")
        res = alg.result
        modes = pick_modes(
            res.Fn_poles,
            res.Xi_poles,
            res.Phi_poles,
            res.Lab,
            k,
            band,
            fn_std=res.Fn_poles_std,
            xi_std=res.Xi_poles_std,
            cut=self.cluster_cut,
        )
        self.last = {"fs": fs, "br": br, "br_capped": capped, "ordmax": ordmax, "refs": refs, "peaks": peaks}
        return modes


def pick_modes(
    fn: np.ndarray,
    xi: np.ndarray,
    phi: np.ndarray,
    lab: np.ndarray,
    k: int,
    band: tuple[float, float],
    fn_std: np.ndarray | None = None,
    xi_std: np.ndarray | None = None,
    cut: float = 0.1,
) -> list[dict]:
    """The modes of a stabilization diagram (pyOMA2's (pole, order) arrays and its stability labels,
    1 = stable): the stable poles inside `band` clustered by average linkage on the distance
    |f_i - f_j| / max(f_i, f_j) + 1 - MAC(phi_i, phi_j), cut at `cut`; the `k` clusters with stable
    poles at the most model orders (ties: more poles) are the modes, each reported by the pole
    nearest its cluster's median frequency (of those, the highest order), with 90 % normal
    intervals from that pole's standard deviations where they are given."""
    from scipy.cluster.hierarchy import fcluster, linkage

    phi = np.asarray(phi)
    sel = (np.asarray(lab) == 1) & np.isfinite(fn) & (fn > band[0]) & (fn < band[1]) & np.isfinite(xi)
    sel &= np.all(np.isfinite(phi), axis=2)
    rows, cols = np.nonzero(sel)
    if rows.size == 0:
        return []
    f, z = fn[rows, cols], xi[rows, cols]
    shapes = phi[rows, cols, :]
    if rows.size == 1:
        labels = np.array([1])
    else:
        norm = np.linalg.norm(shapes, axis=1)
        unit = shapes / np.where(norm > 0, norm, 1.0)[:, None]
        macs = np.abs(unit @ unit.conj().T) ** 2
        dist = np.abs(f[:, None] - f[None, :]) / np.maximum(f[:, None], f[None, :]) + (1.0 - macs)
        dist = 0.5 * (dist + dist.T)
        np.fill_diagonal(dist, 0.0)
        iu = np.triu_indices(f.size, 1)
        labels = fcluster(linkage(np.clip(dist[iu], 0.0, None), method="average"), t=cut, criterion="distance")
    clusters = []
    for c in np.unique(labels):
        members = np.flatnonzero(labels == c)
        clusters.append((np.unique(cols[members]).size, members.size, members))
    clusters.sort(key=lambda x: (x[0], x[1]), reverse=True)
    out = []
    for _, _, members in clusters[:k]:
        med = float(np.median(f[members]))
        dev = np.abs(f[members] - med)
        near = members[dev <= dev.min() * (1 + 1e-12) + 1e-15]
        j = int(near[np.argmax(cols[near])])
        mode: dict[str, Any] = {
            "frequency": float(f[j]),
            "damping_ratio": float(z[j]),
            "shape": _real_shape(shapes[j]),
            "orders": int(np.unique(cols[members]).size),
        }
        if fn_std is not None and xi_std is not None:
            sf, sz = float(fn_std[rows[j], cols[j]]), float(xi_std[rows[j], cols[j]])
            if math.isfinite(sf) and sf > 0:
                mode["frequency_interval"] = (f[j] - Z90 * sf, f[j] + Z90 * sf)
            if math.isfinite(sz) and sz > 0:
                mode["damping_ratio_interval"] = (z[j] - Z90 * sz, z[j] + Z90 * sz)
        out.append(mode)
    return sorted(out, key=lambda m: m["frequency"])


PEERS: dict[str, Callable[[], Method]] = {"ssi-cov": SSICovPeer, "fdd": FDDPeer, "efdd": EFDDPeer}


# ------------------------------------------------------------------ scoring


def match(true_f: Sequence[float], fit_f: Sequence[float], tol: float = MATCH_TOL) -> list[int | None]:
    """For each true frequency the index of the identified one assigned to it (Hungarian assignment
    on the relative frequency difference), or None when the assigned one is not within `tol`."""
    from scipy.optimize import linear_sum_assignment

    out: list[int | None] = [None] * len(true_f)
    if not len(true_f) or not len(fit_f):
        return out
    tf, ff = np.asarray(true_f, float), np.asarray(fit_f, float)
    rel = np.abs(ff[None, :] - tf[:, None]) / tf[:, None]
    # every pair beyond `tol` costs the same large amount: the assignment first matches as many as
    # it can within `tol`, then minimizes their errors (plain relative costs would shift a whole
    # chain of matches by one to make room for a missed mode)
    cost = np.where(np.isfinite(rel) & (rel <= tol), rel, 1e6)
    for r, c in zip(*linear_sum_assignment(cost)):
        if rel[r, c] <= tol:
            out[int(r)] = int(c)
    return out


def mac(a: np.ndarray, b: np.ndarray) -> float:
    """The modal assurance criterion |a^H b|^2 / (|a|^2 |b|^2) (0 for a zero vector)."""
    a, b = np.ravel(a), np.ravel(b)
    den = float(np.real(np.vdot(a, a) * np.vdot(b, b)))
    return float(abs(np.vdot(a, b)) ** 2 / den) if den > 0 else 0.0


def _inside(iv, value: float) -> bool | None:
    if iv is None:
        return None
    lo, hi = float(iv[0]), float(iv[1])
    return bool(lo <= value <= hi) if math.isfinite(lo) and math.isfinite(hi) else None


def _shape_covered(shape: np.ndarray, interval, true_shape: np.ndarray) -> list[bool] | None:
    """Per component, whether the shape's 90 % interval ((channels, 2)) covers the true unit shape,
    the interval scaled by the factor that makes the (real) shape unit-norm with its largest
    component positive (a negative factor swaps the bounds); None without an interval."""
    if interval is None or np.iscomplexobj(shape):
        return None
    iv = np.asarray(interval, float)
    s = np.ravel(shape).astype(float)
    norm = float(np.linalg.norm(s))
    if iv.shape != (s.size, 2) or norm == 0 or not np.all(np.isfinite(iv)):
        return None
    factor = float(np.sign(s[int(np.argmax(np.abs(s)))]) or 1.0) / norm
    lo, hi = np.sort(iv * factor, axis=1).T
    return [bool(a <= t <= b) for a, t, b in zip(lo, true_shape, hi)]


def score(truth: dict, modes: list[dict], close_pair: tuple[int, int] | None = None) -> dict:
    """One data set's scores: per true mode (`modes`: frequency, damping ratio, found, the index of
    the identified mode, frequency relative error, damping absolute and relative error, MAC,
    whether the 90 % intervals cover the truth (f, zeta, and per shape component), None where there
    is no interval), the count of
    identified modes that match none (`spurious`), and whether the close pair is resolved (None
    where the case has none)."""
    tf = np.asarray(truth["frequencies"], float)
    tz = np.asarray(truth["damping_ratios"], float)
    shapes = np.asarray(truth["shapes"], float)
    ff = [float(m["frequency"]) for m in modes]
    assigned = match(tf, ff)
    per = []
    for i, j in enumerate(assigned):
        row: dict[str, Any] = {"frequency": float(tf[i]), "damping_ratio": float(tz[i]), "found": j is not None}
        row.update(index=j, f_rel_error=None, zeta_abs_error=None, zeta_rel_error=None, mac=None)
        row.update(f_covered=None, zeta_covered=None, shape_covered=None)
        if j is not None:
            m = modes[j]
            row["f_rel_error"] = abs(ff[j] - tf[i]) / tf[i]
            z = m.get("damping_ratio")
            if z is not None and math.isfinite(float(z)):
                row["zeta_abs_error"] = abs(float(z) - tz[i])
                row["zeta_rel_error"] = abs(float(z) - tz[i]) / tz[i]
            shape = m.get("shape")
            if shape is not None and np.size(shape) == shapes.shape[0]:
                row["mac"] = mac(_real_shape(np.asarray(shape)), shapes[:, i])
                row["shape_covered"] = _shape_covered(np.asarray(shape), m.get("shape_interval"), shapes[:, i])
            row["f_covered"] = _inside(m.get("frequency_interval"), tf[i])
            row["zeta_covered"] = _inside(m.get("damping_ratio_interval"), tz[i])
        per.append(row)
    resolved = None
    if close_pair is not None:
        a, b = close_pair
        ja, jb = assigned[a], assigned[b]
        resolved = bool(
            ja is not None
            and jb is not None
            and abs(ff[ja] - tf[a]) < abs(ff[ja] - tf[b])
            and abs(ff[jb] - tf[b]) < abs(ff[jb] - tf[a])
        )
    return {
        "modes": per,
        "n_identified": len(modes),
        "spurious": len(modes) - sum(j is not None for j in assigned),
        "pair_resolved": resolved,
    }


def _median(values: list) -> float | None:
    vals = [float(v) for v in values if v is not None and math.isfinite(float(v))]
    return float(np.median(vals)) if vals else None


def _rate(hits: list) -> tuple[float | None, float | None, int]:
    """(fraction, binomial standard error, n) of the non-None booleans."""
    h = [bool(x) for x in hits if x is not None]
    if not h:
        return None, None, 0
    p = float(np.mean(h))
    return p, math.sqrt(p * (1 - p) / len(h)), len(h)


def summarize(fits: list[dict]) -> dict:
    """A method's scores pooled over data sets (`fits`: score dicts with `seconds` and `failed`):
    the fraction of true modes found, medians of the frequency relative error, the damping
    absolute and relative error and the MAC over the matched modes, the close pair's resolution
    rate, the 90 % coverage of f, zeta and the shape components (with its binomial se and the
    number of intervals), the
    spurious modes per data set, failures and the median wall time per fit."""
    rows = [r for f in fits for r in f["modes"]]  # a failed fit's modes count as not found
    good = [f for f in fits if not f.get("failed")]
    cov_f, se_f, n_f = _rate([r["f_covered"] for r in rows])
    cov_z, se_z, n_z = _rate([r["zeta_covered"] for r in rows])
    cov_s, se_s, n_s = _rate([c for r in rows for c in (r.get("shape_covered") or [])])
    pair = [f["pair_resolved"] for f in fits if f.get("pair_resolved") is not None]
    return {
        "n": len(fits),
        "failed": sum(bool(f.get("failed")) for f in fits),
        "found": _rate([r["found"] for r in rows])[0] if rows else 0.0,
        "f_rel_error": _median([r["f_rel_error"] for r in rows]),
        "zeta_abs_error": _median([r["zeta_abs_error"] for r in rows]),
        "zeta_rel_error": _median([r["zeta_rel_error"] for r in rows]),
        "mac": _median([r["mac"] for r in rows]),
        "pair_resolved": _rate([bool(p) for p in pair])[0] if pair else None,
        "f_coverage": cov_f,
        "f_coverage_se": se_f,
        "f_intervals": n_f,
        "zeta_coverage": cov_z,
        "zeta_coverage_se": se_z,
        "zeta_intervals": n_z,
        "shape_coverage": cov_s,
        "shape_coverage_se": se_s,
        "shape_intervals": n_s,
        "spurious": float(np.mean([f["spurious"] for f in good])) if good else None,
        "seconds": _median([f["seconds"] for f in fits]),
    }


# ------------------------------------------------------------------ the run


def _warm_up() -> None:
    """Import what the peers import (pyOMA2 pulls in scikit-learn, pandas, ...: seconds on a cold
    start), so that no peer's first fit is timed with its imports."""
    import importlib

    for name in ("pyoma2.algorithms", "pyoma2.setup", "scipy.cluster.hierarchy", "scipy.optimize", "threadpoolctl"):
        importlib.import_module(name)


def _call(method: Method, ch: Channels, hints: dict) -> tuple[list[dict], float, str | None]:
    """(modes, wall seconds, the failure's first line or None): a method that raises is a result."""
    from threadpoolctl import threadpool_limits

    t0 = time.perf_counter()
    try:
        with quiet(), threadpool_limits(1):
            modes = list(method(ch, dict(hints)))
    except Exception as exc:  # noqa: BLE001 - a failed fit is a result of the bench
        text = (str(exc).strip().splitlines() or [""])[0][:120]
        return [], time.perf_counter() - t0, f"{type(exc).__name__}: {text}"
    return modes, time.perf_counter() - t0, None


def _jsonable(x):
    if isinstance(x, dict):
        return {str(k): _jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_jsonable(v) for v in x]
    if isinstance(x, np.ndarray):
        return _jsonable(x.tolist())
    if isinstance(x, (np.bool_, bool)):
        return bool(x)
    if isinstance(x, (np.integer, int)):
        return int(x)
    if isinstance(x, (np.floating, float)):
        return float(x) if math.isfinite(float(x)) else None
    return x


def _identified(modes: list[dict]) -> list[dict]:
    """The identified modes as JSON (frequency, damping ratio, intervals, shape and its interval)."""
    out = []
    for m in modes:
        d = {key: m.get(key) for key in ("frequency", "damping_ratio", "frequency_interval", "damping_ratio_interval")}
        for key in ("shape", "shape_interval"):
            d[key] = None if m.get(key) is None else np.real(np.asarray(m[key])).astype(float).tolist()
        out.append(_jsonable(d))
    return out


def _resolve_cases(cases: Sequence[str | OMACase] | None, quick: bool) -> list[OMACase]:
    if cases is None:
        return [OMA_CASES[c] for c in QUICK_CASES] if quick else list(OMA_CASES.values())
    out = []
    for c in cases:
        if isinstance(c, OMACase):
            out.append(c)
        elif c in OMA_CASES:
            out.append(OMA_CASES[c])
        else:
            raise ValueError(f"case: {c!r}; allowed: {', '.join(OMA_CASES)}")
    return out


def run(
    quick: bool = False,
    ours: Method | None = None,
    seeds: int = 1,
    cases: Sequence[str | OMACase] | None = None,
    peers: Sequence[str] | None = None,
    log=LOG,
) -> dict[str, Any]:
    """The comparison: every case (QUICK_CASES on their short records with `quick`) over `seeds`
    data sets, fitted by each peer (`peers`, default all of PEERS: ssi-cov, fdd, efdd) and by
    `ours` when given, each with the hints {"modes", "band"}; one method at a time on one BLAS
    thread. Returns (JSON-able) {"rows": one `summarize` row per case and method (with case and
    method), "medians": per method the `summarize` of all its fits, "fits": per case, method and
    data set the scores, the identified modes, seconds and any failure, "cases": each case's
    settings and true modes, "skipped", "settings", "seconds"}."""
    import importlib.util

    t_start = time.perf_counter()
    chosen = _resolve_cases(cases, quick)
    names = list(peers) if peers is not None else list(PEERS)
    for p in names:
        if p not in PEERS:
            raise ValueError(f"peer: {p!r}; allowed: {', '.join(PEERS)}")
    skipped: dict[str, str] = {}
    methods: dict[str, Method] = {}
    if importlib.util.find_spec("pyoma2") is None:
        skipped.update(dict.fromkeys(names, "pyOMA2 is not installed (pip install '.[peers]')"))
    else:
        methods.update({p: PEERS[p]() for p in names})
        _warm_up()
    if ours is not None:
        methods = {"ours": ours, **methods}
    fits: list[dict] = []
    rows: list[dict] = []
    case_info: dict[str, dict] = {}
    for case in chosen:
        hints = case.hints()
        per_method: dict[str, list[dict]] = {m: [] for m in methods}
        for s in range(seeds):
            ch, truth = case.simulate(s, quick)
            if case.name not in case_info:
                case_info[case.name] = _case_info(case, truth, quick)
            for name, method in methods.items():
                if isinstance(method, (FDDPeer, SSICovPeer)):
                    method.last = {}  # a failed fit leaves no stale settings
                modes, seconds, failure = _call(method, ch, hints)
                sc = score(truth, modes, case.close_pair)
                fit = {
                    "case": case.name,
                    "method": name,
                    "seed": case.seed(s),
                    "seconds": seconds,
                    "failed": failure is not None,
                    "note": failure,
                    **sc,
                    "identified": _identified(modes),
                    "settings": dict(getattr(method, "last", None) or {}),
                }
                per_method[name].append(fit)
                fits.append(fit)
        for name in methods:
            row = {"case": case.name, "method": name, **summarize(per_method[name])}
            rows.append(row)
            log(
                f"  {case.name:<15} {name:<8} found {_fmt(row['found'], '.2f')} f_err {_fmt(row['f_rel_error'], '.1e')}"
                f" zeta_err {_fmt(row['zeta_rel_error'], '.2f')} {row['seconds']:.2f} s"
            )
    medians = {name: summarize([f for f in fits if f["method"] == name]) for name in methods}
    return _jsonable(
        {
            "rows": rows,
            "medians": medians,
            "fits": fits,
            "cases": case_info,
            "skipped": skipped,
            "settings": {
                "quick": quick,
                "seeds": seeds,
                "methods": list(methods),
                "match_tolerance": MATCH_TOL,
                "hints": ["modes", "band"],
                "pyoma2": _pyoma2_version(),
            },
            "seconds": time.perf_counter() - t_start,
        }
    )


def _pyoma2_version() -> str | None:
    """The installed pyOMA2's version (its distribution is named pyOMA_2), None when it is not there."""
    from importlib import metadata

    for dist in ("pyOMA_2", "pyOMA-2", "pyoma2"):
        with contextlib.suppress(metadata.PackageNotFoundError):
            return metadata.version(dist)
    return None


def _case_info(case: OMACase, truth: dict, quick: bool) -> dict:
    return {
        "what": case.what,
        "fs": case.fs,
        "duration_s": case.span(quick),
        "channels": list(truth["channels"]),
        "quantity": case.quantity,
        "forcing": case.forcing,
        "noise_rms": case.noise_rms,
        "drift": case.drift,
        "band": list(case.band),
        "close_pair": case.close_pair,
        "frequencies": truth["frequencies"],
        "damping_ratios": truth["damping_ratios"],
    }


def coverage(ours: Method, case: str | OMACase, n_sets: int, quick: bool = False, seed0: int = 0) -> dict:
    """Our estimator over `n_sets` data sets (seeds seed0..) of one case: the 90 % interval coverage
    of the matched modes' frequencies and damping ratios, each with its binomial standard error and
    the number of intervals it rests on, per mode too (and of the shape components, pooled); the
    fraction of modes found, failures and the median wall time."""
    (c,) = _resolve_cases([case], quick)
    hints = c.hints()
    fits = []
    for s in range(seed0, seed0 + n_sets):
        ch, truth = c.simulate(s, quick)
        modes, seconds, failure = _call(ours, ch, hints)
        fits.append({**score(truth, modes, c.close_pair), "seconds": seconds, "failed": failure is not None})
    good = [f for f in fits if not f["failed"]]
    out: dict[str, Any] = {"case": c.name, "n_sets": n_sets, "failed": n_sets - len(good)}
    shape_hits = [c for f in good for r in f["modes"] for c in (r["shape_covered"] or [])]
    p, se, n = _rate(shape_hits)
    out["shape"] = {"coverage": p, "se": se, "n": n}
    for key, name in (("f_covered", "frequency"), ("zeta_covered", "damping_ratio")):
        p, se, n = _rate([r[key] for f in good for r in f["modes"]])
        per_mode = []
        for i, f_true in enumerate(c.frequencies()):
            pm, sm, nm = _rate([f["modes"][i][key] for f in good])
            per_mode.append({"frequency": float(f_true), "coverage": pm, "se": sm, "n": nm})
        out[name] = {"coverage": p, "se": se, "n": n, "per_mode": per_mode}
    out["found"] = _rate([r["found"] for f in good for r in f["modes"]])[0]
    out["seconds"] = _median([f["seconds"] for f in fits])
    return _jsonable(out)


# ------------------------------------------------------------------ table and plot


def _fmt(v, spec: str) -> str:
    """`v` formatted by `spec`; None as "-" right-aligned to the spec's width."""
    width = spec.split(".")[0]
    return format("-", f">{width}") if v is None else format(v, spec)


def table(result: dict[str, Any]) -> str:
    """The rows as fixed-width text, then the medians per method over every fit: found is the
    fraction of true modes matched, f_err the median relative frequency error, z_abs and z_rel the
    damping ratio's median absolute and relative error, mac the median MAC, pair the fraction of
    data sets with the close pair resolved, cov_f and cov_z the 90 % interval coverage (+- its se,
    n intervals), cov_s that of the shape components (n components), spur the identified modes
    matching none per data set, failed the failed fits / data sets, s/fit the median wall time."""
    head = (
        f"{'case':<16}{'method':<9}{'found':>6}{'f_err':>9}{'z_abs':>9}{'z_rel':>7}{'mac':>7}{'pair':>6}"
        f"{'cov_f':>7}{'+-se':>6}{'n':>4}{'cov_z':>7}{'+-se':>6}{'n':>4}{'cov_s':>7}{'n':>5}"
        f"{'spur':>6}{'failed':>8}{'s/fit':>8}"
    )

    def line(case: str, method: str, r: dict) -> str:
        return (
            f"{case:<16}{method:<9}{_fmt(r['found'], '6.2f')}{_fmt(r['f_rel_error'], '9.1e')}"
            f"{_fmt(r['zeta_abs_error'], '9.1e')}{_fmt(r['zeta_rel_error'], '7.2f')}{_fmt(r['mac'], '7.3f')}"
            f"{_fmt(r['pair_resolved'], '6.2f')}{_fmt(r['f_coverage'], '7.2f')}{_fmt(r['f_coverage_se'], '6.2f')}"
            f"{r['f_intervals']:>4}{_fmt(r['zeta_coverage'], '7.2f')}{_fmt(r['zeta_coverage_se'], '6.2f')}"
            f"{r['zeta_intervals']:>4}{_fmt(r['shape_coverage'], '7.2f')}{r['shape_intervals']:>5}"
            f"{_fmt(r['spurious'], '6.1f')}{str(r['failed']) + '/' + str(r['n']):>8}"
            f"{_fmt(r['seconds'], '8.2f')}"
        )

    out = [head]
    out += [line(r["case"], r["method"], r) for r in result.get("rows", [])]
    if result.get("medians"):
        out += ["", "over every case:", head]
        out += [line("all", m, r) for m, r in result["medians"].items()]
    for name, why in result.get("skipped", {}).items():
        out.append(f"skipped {name}: {why}")
    return "\n".join(out)


def plot(result: dict[str, Any], path: str | Path) -> None:
    """Two panels, one point per case and method (colour: method; the method's median over every
    fit as a large marker): the median relative frequency error (left) and the median relative
    damping error (right) against the median wall time per fit, log-log."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = result.get("rows", [])
    methods = list(dict.fromkeys(r["method"] for r in rows))
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.5), constrained_layout=True)
    for ax, key, title in (
        (axes[0], "f_rel_error", "frequency: median relative error"),
        (axes[1], "zeta_rel_error", "damping ratio: median relative error"),
    ):
        for k, m in enumerate(methods):
            sel = [r for r in rows if r["method"] == m and r.get(key) and r.get("seconds")]
            if not sel:
                continue
            ax.scatter([r["seconds"] for r in sel], [r[key] for r in sel], color=f"C{k}", s=25, label=m)
            for r in sel:
                ax.annotate(r["case"], (r["seconds"], r[key]), fontsize=6, alpha=0.7)
            med = result.get("medians", {}).get(m, {})
            if med.get(key) and med.get("seconds"):
                ax.scatter([med["seconds"]], [med[key]], color=f"C{k}", s=140, marker="*", edgecolor="k")
        with contextlib.suppress(ValueError):
            ax.set_xscale("log")
            ax.set_yscale("log")
        ax.set_xlabel("wall time per fit (s)")
        ax.set_title(title)
        ax.grid(True, which="both", alpha=0.3)
    axes[0].scatter([], [], color="w", s=140, marker="*", edgecolor="k", label="median over every fit")
    axes[0].legend(fontsize=8)
    fig.savefig(path, dpi=100, format="png")
    plt.close(fig)


def ours(channels: Channels, hints: dict[str, Any]) -> list[dict]:
    """vibinverse's identification (`vibinverse.oma.identify`) in the bench's method shape: given the
    band but not the mode count (the BIC chooses it per band; the peers are told the count)."""
    from vibinverse.oma import identify

    band = hints.get("band")
    result = identify(channels, band=None if band is None else (float(band[0]), float(band[1])))
    return [
        {
            "frequency": m.frequency,
            "damping_ratio": m.damping_ratio,
            "shape": m.shape,
            "frequency_interval": m.frequency_interval,
            "damping_ratio_interval": m.damping_ratio_interval,
            "shape_interval": m.shape_interval,
        }
        for m in result.modes
    ]
