"""Moves of the nuisance-term search, one small class per idea (emcee's shape: `emcee.moves`), each
saying in its docstring why the data may need it. A move proposes changed `NuisanceSpec`s and never
touches a key the user fixed (`fixed`). `MOVES` holds them in the order the search asks them."""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import replace
from typing import ClassVar

from vibinverse.terms.drift import SCENE_GAIN_TERMS, RandomWalk
from vibinverse.terms.nuisance import DRIFT_TERMS, NO_DRIFT, NO_NOISE, NOISE_TERMS, NuisanceSpec

Proposal = tuple[str, NuisanceSpec]


def _label(terms: dict, kind: str) -> str:
    return terms[kind].label


def _exchanges(spec: NuisanceSpec, field: str, terms: dict) -> list[Proposal]:
    """The spec with `field`'s term exchanged for each other term of its registry."""
    now = getattr(spec, field)
    return [
        (f"{terms[now].label} exchanged for {cls.label}", replace(spec, **{field: kind}))
        for kind, cls in terms.items()
        if cls is not None and kind != now
    ]


class Move(ABC):
    """One way to change the nuisance terms."""

    name: ClassVar[str]
    #: which `NuisanceSpec` fields the move changes (a field the user fixed is never changed)
    changes: ClassVar[tuple[str, ...]]

    def proposals(self, spec: NuisanceSpec, fixed: frozenset[str]) -> list[Proposal]:
        """What this move proposes from `spec` ([] when a field it changes is fixed)."""
        if fixed & set(self.changes):
            return []
        return self.propose(spec)

    @abstractmethod
    def propose(self, spec: NuisanceSpec) -> list[Proposal]:
        """(what changes, in words; the changed spec) for each proposal."""


MOVES: list[Move] = []


def register_move(cls: type[Move]) -> type[Move]:
    """Class decorator: the search asks this move too (`MOVES`)."""
    MOVES.append(cls())
    return cls


@register_move
class AddColouredNoise(Move):
    """AR(1) or 1/f noise beside the white noise. Real sensors are not white: scintillation and
    video compression correlate neighbouring samples, electronics add 1/f (DESIGN.md sec. 8). A
    white-noise likelihood on AR(1) noise (phi 0.9) read the sec. 4.2 roof's 3.46 Hz tilt as a broad
    8.3 Hz resonance of damping ratio 0.5, with confident intervals."""

    name = "add coloured noise"
    changes = ("noise",)

    def propose(self, spec: NuisanceSpec) -> list[Proposal]:
        if spec.coloured:
            return []
        return [(f"{cls.label} added", replace(spec, noise=kind)) for kind, cls in NOISE_TERMS.items() if cls]


@register_move
class AddDrift(Move):
    """A random-walk drift of the level: the sun moves, lamps warm up, a camera changes its exposure;
    all of it is power at the lowest frequencies, often far above the vibration's, which a
    stationary model would put into the resonance (DESIGN.md sec. 8)."""

    name = "add drift"
    changes = ("drift",)

    def propose(self, spec: NuisanceSpec) -> list[Proposal]:
        return [] if spec.drifting else [(f"{RandomWalk.label} added", replace(spec, drift=RandomWalk.kind))]


@register_move
class AddGainDrift(Move):
    """A multiplicative gain drift (SCENE_GAIN_TERMS slow functions up to 4 cycles per record, and a
    constant beside a scene model's fixed level): a cloud dims the whole
    signal, the vibration included, so the resonance's and the lines' amplitudes follow the level;
    an additive drift cannot say that."""

    name = "add gain drift"
    changes = ("gain",)

    def propose(self, spec: NuisanceSpec) -> list[Proposal]:
        return [] if spec.gain else [("gain drift added", replace(spec, gain=SCENE_GAIN_TERMS))]


@register_move
class ExchangeNoise(Move):
    """AR(1) and 1/f exchanged: both put power at low frequencies, and the one added first by the
    greedy step is not always the one the data prefer."""

    name = "exchange noise"
    changes = ("noise",)

    def propose(self, spec: NuisanceSpec) -> list[Proposal]:
        return _exchanges(spec, "noise", NOISE_TERMS) if spec.coloured else []


@register_move
class ExchangeDrift(Move):
    """A random walk and an integrated random walk exchanged: a smooth trend (a slow warm-up, the
    sun's elevation) is an integrated walk's; a ragged one a walk's."""

    name = "exchange drift"
    changes = ("drift",)

    def propose(self, spec: NuisanceSpec) -> list[Proposal]:
        return _exchanges(spec, "drift", DRIFT_TERMS) if spec.drifting else []


@register_move
class DropWhite(Move):
    """The white noise removed beside a coloured noise, which then is the whole noise: where AR(1)
    noise alone describes the data the white noise's sigma is not identified (flat in ln sigma down
    to its prior's bound), which costs the sampler thousands of steps and the intervals nothing."""

    name = "drop white noise"
    changes = ("white",)

    def propose(self, spec: NuisanceSpec) -> list[Proposal]:
        if not spec.coloured or not spec.white:
            return []
        return [("white noise removed", replace(spec, white=False))]


@register_move
class AddWhite(Move):
    """The white noise put back beside a coloured noise (the search may have removed it early)."""

    name = "add white noise"
    changes = ("white",)

    def propose(self, spec: NuisanceSpec) -> list[Proposal]:
        return [] if spec.white else [("white noise added", replace(spec, white=True))]


@register_move
class DropTerm(Move):
    """A nuisance term removed (the backward step): the greedy forward step may keep a term that a
    later one makes unnecessary, e.g. a drift beside a slow AR(1) noise."""

    name = "drop a term"
    changes = ()

    def proposals(self, spec: NuisanceSpec, fixed: frozenset[str]) -> list[Proposal]:
        out = []
        if spec.coloured and "noise" not in fixed and (spec.white or "white" not in fixed):
            out.append((f"{_label(NOISE_TERMS, spec.noise)} removed", replace(spec, noise=NO_NOISE, white=True)))
        if spec.drifting and "drift" not in fixed:
            out.append((f"{_label(DRIFT_TERMS, spec.drift)} removed", replace(spec, drift=NO_DRIFT)))
        if spec.gain and "gain" not in fixed:
            out.append(("gain drift removed", replace(spec, gain=0)))
        return out

    def propose(self, spec: NuisanceSpec) -> list[Proposal]:
        return self.proposals(spec, frozenset())
