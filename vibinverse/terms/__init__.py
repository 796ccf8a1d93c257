"""Terms a model is a sum of (`Oscillator() + AR1() + RandomWalk() + White()`), each owning its
parameters, priors, starts, state-space block, observation row, PSD and description; `nuisance`
builds the nuisance terms a table or the command line asks for."""

from vibinverse.engines.state_space import StateSpace
from vibinverse.terms.base import TERMS, DataFacts, Term, TermSum, register_term
from vibinverse.terms.decay import FreeDecay
from vibinverse.terms.drift import GainDrift, IntegratedWalk, RandomWalk
from vibinverse.terms.noise import AR1, Flicker, White
from vibinverse.terms.resonance import Oscillator

__all__ = [
    "AR1",
    "TERMS",
    "DataFacts",
    "Flicker",
    "FreeDecay",
    "GainDrift",
    "IntegratedWalk",
    "Oscillator",
    "RandomWalk",
    "StateSpace",
    "Term",
    "TermSum",
    "White",
    "register_term",
]
